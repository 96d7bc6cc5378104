//! plenoptic-io's glTF/GLB mesh loader (`read_mesh` on a `.gltf`; the importer tells GLB from
//! JSON by its magic). The buffers and texture of the seed files sit beside it under their
//! own names, so mutated seeds still reach the accessor and image code.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    static INIT: std::sync::Once = std::sync::Once::new();
    INIT.call_once(|| {
        transcoder_fuzz::scratch_file(
            "BoxTextured0.bin",
            include_bytes!("../../testdata/meshes/box-textured/BoxTextured0.bin"),
        );
        transcoder_fuzz::scratch_file(
            "CesiumLogoFlat.png",
            include_bytes!("../../testdata/meshes/box-textured/CesiumLogoFlat.png"),
        );
        transcoder_fuzz::scratch_file(
            "IndexOutOfRange.bin",
            include_bytes!("../../testdata/bad/gltf/IndexOutOfRange/IndexOutOfRange.bin"),
        );
        transcoder_fuzz::allow_caught_reader_panics();
    });
    let path = transcoder_fuzz::scratch_file("fuzz.gltf", data);
    let _ = plenoptic_io::read_mesh(&path);
});
