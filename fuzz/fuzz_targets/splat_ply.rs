//! splat-core's 3DGS PLY reader (`parse_splats`, what `read_splats` runs on the file's bytes).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_core::ply::parse_splats(std::path::Path::new("fuzz.ply"), data);
});
