//! One writer at a time: an advisory lock on a file in the folder being written.
//!
//! Two processes writing one output folder clear and rewrite each other's files (a Slurm task
//! requeued while its first attempt still runs, an array submitted twice, two overlapping shard
//! specs): frames failed with "checkpoint: No such file" and the last writer's manifest won. A
//! run holds `OUT/.transcode.lock` (a shard `OUT/shards/.shard-I-of-N.lock`) while it writes,
//! through the operating system's file lock (`flock` on Unix, `LockFileEx` on Windows), which
//! the system releases when the process ends however it ends, so a killed run leaves no stale
//! lock behind. The lock is advisory: it keeps transcode processes apart, not other programs; on
//! a file system that cannot lock (some network mounts) a run goes on unguarded.

use std::fs::{File, OpenOptions, TryLockError};
use std::path::{Path, PathBuf};

/// A held lock; released when dropped.
#[derive(Debug)]
pub struct WriterLock {
    _file: File,
}

/// Why a lock was not taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another process holds it.
    #[error(
        "another transcode process is writing here (it holds {0}): wait for it to end, or write \
         elsewhere"
    )]
    Held(PathBuf),
    /// The lock file cannot be created or locked.
    #[error("{path}: cannot take the writer's lock: {source}")]
    Io {
        /// The lock file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

impl WriterLock {
    /// Takes the lock on `path` (created, with its folder, when missing), without waiting; where
    /// the file system cannot lock, the lock is taken as held by this run alone.
    ///
    /// # Errors
    /// [`LockError::Held`] when another process (or another open handle of this one) holds it;
    /// [`LockError::Io`] when the file cannot be created.
    pub fn acquire(path: &Path) -> Result<Self, LockError> {
        let io = |source| LockError::Io {
            path: path.to_path_buf(),
            source,
        };
        if let Some(folder) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(folder).map_err(io)?;
        }
        let file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(path)
            .map_err(io)?;
        match file.try_lock() {
            // A file system that cannot lock at all (some network mounts answer ENOLCK) leaves
            // the run unguarded rather than refused: the lock only keeps two runs apart.
            Ok(()) | Err(TryLockError::Error(_)) => Ok(Self { _file: file }),
            Err(TryLockError::WouldBlock) => Err(LockError::Held(path.to_path_buf())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_writer_is_refused_until_the_first_lets_go() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out/.transcode.lock");
        let first = WriterLock::acquire(&path).unwrap();
        // A second handle conflicts as a second process would.
        let err = WriterLock::acquire(&path).unwrap_err();
        assert!(matches!(&err, LockError::Held(p) if p == &path), "{err}");
        assert!(
            err.to_string().contains("another transcode process"),
            "{err}"
        );
        drop(first);
        let _again = WriterLock::acquire(&path).unwrap();
    }
}
