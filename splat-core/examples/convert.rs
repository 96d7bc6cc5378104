//! Converts a splat model between formats with this crate's readers and writers (used by the
//! gsply and glTF-validator interop tests, and handy on its own).
//!
//! `convert IN OUT [SH1_BITS SH_REST_BITS]`: IN is a 3DGS `.ply` or an `.spz`; OUT is a `.ply`,
//! an `.spz` (version 3; Niantic's default 5/4 SH bits unless given) or a `.glb`
//! (`KHR_gaussian_splatting`).

use std::path::Path;

use splat_core::{glb, ply, spz};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output, bits @ ..] = args.as_slice() else {
        return Err("usage: convert IN.(ply|spz) OUT.(ply|spz|glb) [SH1_BITS SH_REST_BITS]".into());
    };
    let ext = |p: &str| {
        Path::new(p)
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase()
    };
    let splats = match ext(input).as_str() {
        "ply" => ply::read_splats(Path::new(input))?,
        "spz" => spz::read_spz(Path::new(input))?.splats,
        other => return Err(format!("{input}: unknown input format `{other}`").into()),
    };
    match ext(output).as_str() {
        "ply" => ply::write_splats(Path::new(output), &splats)?,
        "glb" => glb::write_glb(Path::new(output), &splats)?,
        "spz" => {
            let mut options = spz::SpzOptions::default();
            if let [sh1, rest] = bits {
                options.sh1_bits = sh1.parse()?;
                options.sh_rest_bits = rest.parse()?;
            }
            spz::write_spz(Path::new(output), &splats, &options)?;
        }
        other => return Err(format!("{output}: unknown output format `{other}`").into()),
    }
    Ok(())
}
