//! Any bytes given to the PLY parser must give a cloud, a mesh or a typed error, never a panic
//! or an unbounded allocation.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let name = Path::new("fuzz.ply");
    let _ = plenoptic_io::ply::cloud_from_bytes(name, data);
    let _ = plenoptic_io::ply::model_from_bytes(name, data);
});
