//! splat-core's `.splat` reader (`export::decode_splat`, what `read_splat` runs on the file's
//! bytes).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = splat_core::export::decode_splat(std::path::Path::new("fuzz.splat"), data);
});
