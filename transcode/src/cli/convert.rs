//! `transcode convert IN OUT [--sh1-bits N] [--sh-rest-bits N]`: converts a splat model between
//! the 3DGS PLY, SPZ, the antimatter15 `.splat` and `.glb` (`KHR_gaussian_splatting`), each
//! chosen by its file extension, and writes the output atomically.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use splat_core::{Splats, export, glb, ply, spz};

/// Arguments of `transcode convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model to read: `.ply` (3DGS, Inria layout), `.spz`, `.splat` or `.glb`.
    pub input: PathBuf,
    /// The file to write, by extension: `.ply`, `.spz` (version 3), `.splat` or `.glb`.
    pub output: PathBuf,
    /// SPZ output: bits kept of each degree-1 SH coefficient, 1–8 (default 5, Niantic's).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=8))]
    pub sh1_bits: Option<u8>,
    /// SPZ output: bits kept of each degree-2 and degree-3 SH coefficient, 1–8 (default 4).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=8))]
    pub sh_rest_bits: Option<u8>,
}

/// The splat formats `convert` reads and writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ply,
    Spz,
    Splat,
    Glb,
}

impl Format {
    /// The format named by `path`'s extension (case-insensitive).
    fn of(path: &Path) -> anyhow::Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        Ok(match ext.as_deref() {
            Some("ply") => Self::Ply,
            Some("spz") => Self::Spz,
            Some("splat") => Self::Splat,
            Some("glb") => Self::Glb,
            _ => bail!(
                "{}: unknown splat format {}; convert reads and writes .ply (3DGS), .spz, .splat \
                 and .glb",
                path.display(),
                ext.map_or_else(|| "(no extension)".to_string(), |e| format!("`.{e}`"))
            ),
        })
    }
}

/// Converts the input model to the output's format and prints what was written.
pub fn run(args: Args) -> anyhow::Result<()> {
    let (from, to) = (Format::of(&args.input)?, Format::of(&args.output)?);
    if to != Format::Spz && (args.sh1_bits.is_some() || args.sh_rest_bits.is_some()) {
        bail!("--sh1-bits and --sh-rest-bits apply to .spz output only");
    }
    let mut antialiased = false;
    let splats: Splats = match from {
        Format::Ply => ply::read_splats(&args.input)?,
        Format::Spz => {
            let m = spz::read_spz(&args.input)?;
            antialiased = m.antialiased;
            m.splats
        }
        Format::Splat => export::read_splat(&args.input)?,
        Format::Glb => glb::read_glb(&args.input)?,
    };
    if to == Format::Splat && splats.sh_degree > 0 {
        println!(
            "warning: .splat keeps only the diffuse colour: the SH bands of degree 1–{} (view \
             dependence) are dropped",
            splats.sh_degree
        );
    }
    if antialiased && to != Format::Spz {
        println!(
            "warning: the SPZ file says the model was trained antialiased; {} has no place for \
             that flag (render it with --antialiased)",
            args.output.display()
        );
    }
    match to {
        Format::Ply => ply::write_splats(&args.output, &splats)?,
        Format::Spz => {
            let defaults = spz::SpzOptions::default();
            let options = spz::SpzOptions {
                sh1_bits: args.sh1_bits.unwrap_or(defaults.sh1_bits),
                sh_rest_bits: args.sh_rest_bits.unwrap_or(defaults.sh_rest_bits),
                antialiased,
                ..defaults
            };
            spz::write_spz(&args.output, &splats, &options)?;
        }
        Format::Splat => export::write_splat(&args.output, &splats)?,
        Format::Glb => glb::write_glb(&args.output, &splats)?,
    }
    let size = |p: &Path| {
        std::fs::metadata(p)
            .map(|m| m.len())
            .with_context(|| format!("reading the size of {}", p.display()))
    };
    let (bytes_in, bytes_out) = (size(&args.input)?, size(&args.output)?);
    let degree = if to == Format::Splat {
        0
    } else {
        splats.sh_degree
    };
    println!(
        "wrote {}: {} splats, SH degree {degree}, {bytes_out} bytes ({:.2}× the {bytes_in}-byte \
         input)",
        args.output.display(),
        splats.len(),
        bytes_out as f64 / bytes_in.max(1) as f64,
    );
    Ok(())
}
