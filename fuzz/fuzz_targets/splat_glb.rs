//! splat-core's `.glb` reader (`glb::decode_glb`, what `read_glb` runs on the file's bytes).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_core::glb::decode_glb(std::path::Path::new("fuzz.glb"), data);
});
