//! Writes 3DGS PLY files with this crate's writer (used by the plyfile interop test).
//!
//! `write_ply copy IN.ply OUT.ply` reads any 3DGS PLY and writes it back in Inria's layout;
//! `write_ply synthetic OUT.ply DEGREE` writes 7 splats whose every value follows a formula the
//! test recomputes: mean = 0.5·(i, 2i, 3i), log-scale = (−0.1·i, −1, 0.25),
//! rotation = (1, 0.1·i, 0, −0.2), opacity logit = i − 3, SH[k][c] = 0.01·(100·i + 10·k + c).

use std::path::Path;

use glam::Vec3;
use splat_core::{Splats, num_sh_coeffs, ply};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["copy", input, output] => {
            let s = ply::read_splats(Path::new(input))?;
            ply::write_splats(Path::new(output), &s)?;
        }
        ["synthetic", output, degree] => {
            let degree: u32 = degree.parse()?;
            let mut s = Splats::new(degree);
            for i in 0..7 {
                let f = i as f32;
                let sh: Vec<[f32; 3]> = (0..num_sh_coeffs(degree))
                    .map(|k| {
                        std::array::from_fn(|c| 0.01 * (100.0 * f + 10.0 * k as f32 + c as f32))
                    })
                    .collect();
                s.push(
                    0.5 * Vec3::new(f, 2.0 * f, 3.0 * f),
                    Vec3::new(-0.1 * f, -1.0, 0.25),
                    [1.0, 0.1 * f, 0.0, -0.2],
                    f - 3.0,
                    &sh,
                );
            }
            ply::write_splats(Path::new(output), &s)?;
        }
        _ => {
            return Err(
                "usage: write_ply copy IN.ply OUT.ply | write_ply synthetic OUT.ply DEGREE".into(),
            );
        }
    }
    Ok(())
}
