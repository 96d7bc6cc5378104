//! plenoptic-io's PLY reader, header and body: the whole file as a point cloud
//! (`cloud_from_bytes`, what `read_cloud` runs) and as a mesh or cloud (`model_from_bytes`,
//! what `load` and the mesh-PLY path of `read_mesh` run).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Relative texture names (`comment TextureFile ...`) resolve inside the scratch directory.
    let name = transcoder_fuzz::scratch_dir().join("fuzz.ply");
    let _ = plenoptic_io::ply::cloud_from_bytes(&name, data);
    let _ = plenoptic_io::ply::model_from_bytes(&name, data);
});
