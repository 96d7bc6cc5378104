//! Converts between the Inria 3DGS PLY and SPZ with this crate's reader and writer (used by the
//! gsply interop test, and handy on its own).
//!
//! `spz encode IN.ply OUT.spz [SH1_BITS SH_REST_BITS]` writes an SPZ (version 3, Niantic's
//! default 5/4 SH bits unless given); `spz decode IN.spz OUT.ply` writes the splats back as a PLY.

use std::path::Path;

use splat_core::{ply, spz};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["encode", input, output, bits @ ..] => {
            let mut options = spz::SpzOptions::default();
            if let [sh1, rest] = bits {
                options.sh1_bits = sh1.parse()?;
                options.sh_rest_bits = rest.parse()?;
            }
            let splats = ply::read_splats(Path::new(input))?;
            spz::write_spz(Path::new(output), &splats, &options)?;
        }
        ["decode", input, output] => {
            let model = spz::read_spz(Path::new(input))?;
            ply::write_splats(Path::new(output), &model.splats)?;
        }
        _ => return Err(
            "usage: spz encode IN.ply OUT.spz [SH1_BITS SH_REST_BITS] | spz decode IN.spz OUT.ply"
                .into(),
        ),
    }
    Ok(())
}
