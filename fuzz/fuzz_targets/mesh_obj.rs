//! plenoptic-io's OBJ mesh loader (`read_mesh` on a `.obj`, through tobj). The bytes become
//! `fuzz.obj`; a small `fuzz.mtl` beside it lets `mtllib fuzz.mtl` resolve.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    static INIT: std::sync::Once = std::sync::Once::new();
    INIT.call_once(|| {
        transcoder_fuzz::scratch_file("fuzz.mtl", b"newmtl a\nKd 0.5 0.25 1\nd 0.5\n");
        transcoder_fuzz::allow_caught_reader_panics();
    });
    let path = transcoder_fuzz::scratch_file("fuzz.obj", data);
    let _ = plenoptic_io::read_mesh(&path);
});
