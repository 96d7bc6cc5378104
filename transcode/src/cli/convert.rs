//! `transcode convert IN OUT [--sh1-bits N] [--sh-rest-bits N] [--spz-version 3|4]`: converts a
//! splat model between the 3DGS PLY, SPZ (versions 2–4 read, 3 or 4 written), the antimatter15
//! `.splat` and `.glb` (`KHR_gaussian_splatting`), each chosen by its file extension, and writes
//! the output atomically.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use splat_core::model_file::{self, Format};
use splat_core::spz;

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
    /// SPZ output: format version 3 (one gzip stream, the default, which every SPZ reader
    /// reads) or 4 (zstd streams, Niantic's latest).
    #[arg(long, value_parser = clap::value_parser!(u32).range(3..=4))]
    pub spz_version: Option<u32>,
}

/// Converts the input model to the output's format and prints what was written.
pub fn run(args: Args) -> anyhow::Result<()> {
    let to = Format::of(&args.output)?;
    Format::of(&args.input)?;
    if to != Format::Spz
        && (args.sh1_bits.is_some() || args.sh_rest_bits.is_some() || args.spz_version.is_some())
    {
        bail!("--sh1-bits, --sh-rest-bits and --spz-version apply to .spz output only");
    }
    // Convert reads the whole input before it writes, but the atomic write would still replace
    // the input with its own conversion (a lossy SPZ over its PLY, say).
    super::outputs::refuse_overwriting_inputs(&args.output, "output", &[&args.input], &[])?;
    let model = model_file::read_model(&args.input)?;
    let splats = &model.splats;
    if splats.is_empty() {
        println!(
            "warning: {} holds no splats: {} will hold none",
            args.input.display(),
            args.output.display()
        );
    }
    if to == Format::Spz {
        let clamped = spz::clamped_by_spz(splats);
        for (count, what) in [
            (clamped.log_scales, "a log-scale outside SPZ's [-10, 5.94]"),
            (
                clamped.colours,
                "a DC colour coefficient outside SPZ's ±3.33",
            ),
            (
                clamped.sh,
                "a higher SH coefficient outside SPZ's [-1, 0.99]",
            ),
        ] {
            if count > 0 {
                println!(
                    "warning: {count} splat(s) of {} have {what}: clamped into the range in {}, \
                     as Niantic's encoder does",
                    args.input.display(),
                    args.output.display()
                );
            }
        }
    }
    if model.skipped_extensions {
        println!(
            "warning: {} holds SPZ extension records, which are not read (a tool's extension can \
             change how its splats are meant to be read); they are not written to {}",
            args.input.display(),
            args.output.display()
        );
    }
    if to == Format::Splat && splats.sh_degree > 0 {
        println!(
            "warning: .splat keeps only the diffuse colour: the SH bands of degree 1–{} (view \
             dependence) are dropped",
            splats.sh_degree
        );
    }
    if model.antialiased && !to.records_antialiased() {
        println!(
            "warning: {} says the model was trained antialiased; {} has no place for that, so \
             viewers will draw it plain, with more coverage than it was trained to have (keep \
             it as .ply or .spz, which say so, or render it with --antialiased)",
            args.input.display(),
            args.output.display()
        );
    }
    let defaults = spz::SpzOptions::default();
    let spz_options = spz::SpzOptions {
        sh1_bits: args.sh1_bits.unwrap_or(defaults.sh1_bits),
        sh_rest_bits: args.sh_rest_bits.unwrap_or(defaults.sh_rest_bits),
        version: args.spz_version.unwrap_or(defaults.version),
        ..defaults
    };
    model_file::write_model(&args.output, splats, model.antialiased, &spz_options)?;
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
