//! colmap-io's binary readers. The first byte picks the file the rest becomes (0: cameras.bin,
//! 1: images.bin, 2: points3D.bin); the other two hold a count of zero (a valid empty model),
//! and `read_model_as` reads all three and cross-checks them.
#![no_main]

use colmap_io::Format;
use libfuzzer_sys::fuzz_target;

const FILES: [&str; 3] = ["cameras.bin", "images.bin", "points3D.bin"];

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let which = usize::from(which) % 3;
    for (i, name) in FILES.iter().enumerate() {
        transcoder_fuzz::scratch_file(name, if i == which { rest } else { &[0u8; 8] });
    }
    let _ = colmap_io::read_model_as(transcoder_fuzz::scratch_dir(), Format::Binary);
});
