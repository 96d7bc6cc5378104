//! A splat model file in any format this crate reads and writes, chosen by its extension, with
//! the one thing besides the splats that a file can say: whether the model is drawn with the
//! antialiased (Mip-Splatting) opacity compensation it was trained with.

use std::path::Path;

use crate::{Error, Splats, export, glb, ply, spz};

/// The splat file formats, each named by its extension (case-insensitive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// The Inria 3DGS PLY ([`ply`]).
    Ply,
    /// Niantic's SPZ ([`spz`]).
    Spz,
    /// The antimatter15 `.splat` ([`export`]).
    Splat,
    /// Binary glTF with `KHR_gaussian_splatting` ([`glb`]).
    Glb,
}

impl Format {
    /// The format `path`'s extension names, or [`Error::UnknownFormat`].
    pub fn of(path: &Path) -> Result<Self, Error> {
        let ext = path.extension().and_then(|e| e.to_str());
        match ext.map(str::to_ascii_lowercase).as_deref() {
            Some("ply") => Ok(Self::Ply),
            Some("spz") => Ok(Self::Spz),
            Some("splat") => Ok(Self::Splat),
            Some("glb") => Ok(Self::Glb),
            _ => Err(Error::UnknownFormat {
                path: path.to_path_buf(),
                extension: ext.map_or_else(|| "(no extension)".to_string(), |e| format!("`.{e}`")),
            }),
        }
    }

    /// Whether a file of this format can say that its model is drawn antialiased: a PLY's
    /// header comment and an SPZ's flag can; `.splat` and glTF have no place for it, so
    /// viewers draw what they hold plain.
    #[must_use]
    pub fn records_antialiased(self) -> bool {
        matches!(self, Self::Ply | Self::Spz)
    }
}

/// A model read from a file of any [`Format`].
#[derive(Clone, Debug, PartialEq)]
pub struct ModelFile {
    /// The splats, in this crate's frame.
    pub splats: Splats,
    /// The file says the model is drawn antialiased ([`ply::ANTIALIASED_COMMENT`], SPZ's flag);
    /// always false for the formats that cannot say it.
    pub antialiased: bool,
    /// The file's format.
    pub format: Format,
    /// An SPZ file's format version (2, 3 or 4); `None` for the other formats.
    pub spz_version: Option<u32>,
    /// The file held records this crate skips (a version 4 SPZ's extensions,
    /// [`spz::SpzModel::skipped_extensions`]).
    pub skipped_extensions: bool,
}

/// Reads a model file in the format its extension names.
pub fn read_model(path: &Path) -> Result<ModelFile, Error> {
    let format = Format::of(path)?;
    let (splats, antialiased, spz_version, skipped_extensions) = match format {
        Format::Ply => {
            let m = ply::read_model(path)?;
            (m.splats, m.antialiased, None, false)
        }
        Format::Spz => {
            let m = spz::read_spz(path)?;
            (
                m.splats,
                m.antialiased,
                Some(m.version),
                m.skipped_extensions,
            )
        }
        Format::Splat => (export::read_splat(path)?, false, None, false),
        Format::Glb => (glb::read_glb(path)?, false, None, false),
    };
    Ok(ModelFile {
        splats,
        antialiased,
        format,
        spz_version,
        skipped_extensions,
    })
}

/// Writes `splats` in the format `path`'s extension names, atomically, marked antialiased
/// where the format can say so; SPZ output takes its packing from `spz_options` (its own
/// antialiased flag is replaced by `antialiased`).
pub fn write_model(
    path: &Path,
    splats: &Splats,
    antialiased: bool,
    spz_options: &spz::SpzOptions,
) -> Result<Format, Error> {
    let format = Format::of(path)?;
    match format {
        Format::Ply => ply::write_model(path, splats, &ply::PlyOptions { antialiased })?,
        Format::Spz => spz::write_spz(
            path,
            splats,
            &spz::SpzOptions {
                antialiased,
                ..*spz_options
            },
        )?,
        Format::Splat => export::write_splat(path, splats)?,
        Format::Glb => glb::write_glb(path, splats)?,
    }
    Ok(format)
}
