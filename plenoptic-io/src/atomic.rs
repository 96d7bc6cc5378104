//! Atomic file output: write to a temporary file beside the target, then rename over it.

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::Error;

/// Writes `path` through `fill` so that readers see either the old file or the complete new one.
pub(crate) fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), Error> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let temp = path.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| {
        let file = std::fs::File::create(&temp)?;
        let mut writer = BufWriter::with_capacity(1 << 20, file);
        fill(&mut writer)?;
        writer.flush()?;
        writer.get_ref().sync_all()?;
        std::fs::rename(&temp, path)
    })();
    result.map_err(|e| {
        // Best effort: the temporary file is useless after a failure.
        let _ = std::fs::remove_file(&temp);
        Error::io(path, e)
    })
}
