//! colmap-io's text readers. The first byte picks the file the rest becomes (0: cameras.txt,
//! 1: images.txt, 2: points3D.txt); the other two are empty (a valid empty model), and
//! `read_model_as` reads all three and cross-checks them.
#![no_main]

use colmap_io::Format;
use libfuzzer_sys::fuzz_target;

const FILES: [&str; 3] = ["cameras.txt", "images.txt", "points3D.txt"];

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let which = usize::from(which) % 3;
    for (i, name) in FILES.iter().enumerate() {
        transcoder_fuzz::scratch_file(name, if i == which { rest } else { b"" });
    }
    let _ = colmap_io::read_model_as(transcoder_fuzz::scratch_dir(), Format::Text);
});
