//! Atomic file output: readers of a file written here see either the old file or the complete
//! new one, never a half-written file.
//!
//! - [`write_atomic`]: writes bytes already in memory.
//! - [`write_atomic_with`]: streams through a 1 MiB [`BufWriter`] on the temporary file.
//! - [`stale_temporary_target`]: recognises a temporary a killed writer left behind.
//!
//! Both write a temporary sibling of the target (in the same folder, so the rename cannot cross
//! file systems), named from the target's file name, the process id and a process-wide counter,
//! so two threads or processes writing into one folder never share a temporary. The temporary
//! is flushed, `fsync`ed and renamed over the target; on Unix the folder is then `fsync`ed (best
//! effort). On any failure the temporary is removed and an existing file at the target is left
//! untouched. Errors are plain [`std::io::Error`]s; callers wrap them with the path in their own
//! error types.
//!
//! A target that is a symbolic link is written through it, as `cp` writes: the file the link
//! names is replaced (or created, where the link dangles) and the link stays. A file that is
//! replaced keeps its permissions (a private `0600` model stays private).
//!
//! ```
//! use std::io::Write;
//!
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("numbers.txt");
//! atomic_output::write_atomic(&path, b"1 2 3\n")?;
//! atomic_output::write_atomic_with(&path, |w| writeln!(w, "4 5 6"))?;
//! assert_eq!(std::fs::read_to_string(&path)?, "4 5 6\n");
//! // Only the target is left in the folder.
//! assert_eq!(std::fs::read_dir(dir.path())?.count(), 1);
//! # Ok::<(), std::io::Error>(())
//! ```

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Capacity of the buffered writer handed to the `fill` closure of [`write_atomic_with`].
const BUFFER_BYTES: usize = 1 << 20;

/// Distinguishes the temporaries of concurrent writes within one process.
static NEXT_TEMPORARY: AtomicU64 = AtomicU64::new(0);

/// Writes `bytes` to `path` atomically (temporary sibling, flush, `fsync`, rename).
///
/// # Errors
/// Any I/O error creating, writing, syncing or renaming the temporary file (for example when
/// the folder of `path` does not exist); the temporary is then removed and an old file at
/// `path` is left as it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Writes `path` atomically through `fill`, which receives a 1 MiB buffered writer on a
/// temporary sibling file; the file appears under its name only if `fill`, the flush, the
/// `fsync` and the rename all succeed.
///
/// # Errors
/// The first error of `fill` or of the file system; the temporary is then removed and an old
/// file at `path` is left as it was.
pub fn write_atomic_with<F>(path: &Path, fill: F) -> std::io::Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
{
    let path = &through_links(path);
    let temp = temporary_sibling(path);
    let result = (|| {
        let file = File::create(&temp).map_err(|e| explain_create(e, path))?;
        let mut writer = BufWriter::with_capacity(BUFFER_BYTES, file);
        fill(&mut writer)?;
        writer.flush()?;
        writer.get_ref().sync_all()?;
        drop(writer);
        if let Ok(old) = std::fs::metadata(path) {
            std::fs::set_permissions(&temp, old.permissions())?;
        }
        std::fs::rename(&temp, path)
    })();
    if let Err(e) = result {
        // Best effort: the temporary is useless after a failure (and may not exist at all).
        let _ = std::fs::remove_file(&temp);
        return Err(e);
    }
    sync_parent(path);
    Ok(())
}

/// The file `path` names once its symbolic links are followed (a relative link from the
/// link's own folder), whether or not that file exists yet; `path` itself when it is no link.
/// Gives up after 40 links (a loop), as the kernel does, leaving the rename to replace the
/// last one.
fn through_links(path: &Path) -> PathBuf {
    let mut path = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::read_link(&path) {
            Ok(target) => {
                path = match path.parent() {
                    Some(folder) if target.is_relative() => folder.join(target),
                    _ => target,
                };
            }
            Err(_) => break,
        }
    }
    path
}

/// The temporary's creation failed: where the folder is missing or is not a folder, says so
/// (the bare `No such file or directory` reads as if the file itself were expected to exist).
fn explain_create(e: std::io::Error, path: &Path) -> std::io::Error {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => return e,
    };
    let problem = match std::fs::metadata(folder) {
        Err(_) => "does not exist",
        Ok(m) if !m.is_dir() => "is not a folder",
        Ok(_) => return e,
    };
    std::io::Error::new(
        e.kind(),
        format!("the folder {} {problem}", folder.display()),
    )
}

/// The temporary used while `path` is written: `.NAME.PID.N.tmp` in the same folder.
fn temporary_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let n = NEXT_TEMPORARY.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{name}.{}.{n}.tmp", std::process::id()))
}

/// The file name a temporary of this crate was writing, when `file_name` is one
/// (`.NAME.PID.N.tmp`) left by a process that is no longer running, as a process killed
/// mid-write leaves it: `NAME`. `None` for other names, for this process's own temporaries, and
/// where it cannot be told whether the writer still runs (no `/proc`), so that a caller
/// clearing stale files never takes a temporary another process is still writing.
#[must_use]
pub fn stale_temporary_target(file_name: &str) -> Option<&str> {
    let inner = file_name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (rest, n) = inner.rsplit_once('.')?;
    let (name, pid) = rest.rsplit_once('.')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if name.is_empty() || !digits(n) || !digits(pid) {
        return None;
    }
    let pid: u32 = pid.parse().ok()?;
    let proc_fs = Path::new("/proc/self");
    let stale = pid != std::process::id()
        && proc_fs.exists()
        && !Path::new("/proc").join(pid.to_string()).exists();
    stale.then_some(name)
}

/// Syncs the folder holding `path`, best effort.
///
/// The rename replaces a directory entry, and the entry lives in the folder, not in the file:
/// `sync_all` on the file makes its content durable, but only an `fsync` of the folder makes
/// the rename itself survive a power cut (otherwise the old file, or no file, may come back).
/// Failure is ignored: the new file is complete and in place either way, and some file systems
/// refuse to sync a directory.
#[cfg(unix)]
fn sync_parent(path: &Path) {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if let Ok(dir) = File::open(parent) {
        let _ = dir.sync_all();
    }
}

/// Elsewhere a folder cannot be opened as a file; the rename is as durable as the platform makes it.
#[cfg(not(unix))]
fn sync_parent(_path: &Path) {}

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn writes_the_whole_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        let bytes: Vec<u8> = (0..3_000_000u32).map(|i| (i % 251) as u8).collect();
        write_atomic(&p, &bytes).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), bytes);
        write_atomic(&p, b"shorter").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"shorter");
        assert_eq!(entries(dir.path()), ["out.bin"]);
    }

    #[test]
    fn streams_through_fill() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.txt");
        write_atomic_with(&p, |w| {
            for i in 0..3 {
                writeln!(w, "line {i}")?;
            }
            Ok(())
        })
        .unwrap();
        assert_eq!(
            std::fs::read_to_string(&p).unwrap(),
            "line 0\nline 1\nline 2\n"
        );
        assert_eq!(entries(dir.path()), ["out.txt"]);
    }

    #[test]
    fn a_failing_fill_leaves_nothing_behind_and_the_old_file_intact() {
        let dir = tempfile::tempdir().unwrap();
        let fresh = dir.path().join("fresh.bin");
        let err = write_atomic_with(&fresh, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(err.to_string(), "disk full");
        assert!(!fresh.exists());
        assert!(entries(dir.path()).is_empty());

        let old = dir.path().join("old.bin");
        std::fs::write(&old, b"old content").unwrap();
        let err = write_atomic_with(&old, |w| {
            w.write_all(&vec![7u8; 2 << 20])?;
            Err(std::io::Error::other("cancelled"))
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read(&old).unwrap(), b"old content");
        assert_eq!(entries(dir.path()), ["old.bin"]);
    }

    #[test]
    fn many_threads_write_into_one_folder_at_once() {
        let dir = tempfile::tempdir().unwrap();
        std::thread::scope(|s| {
            for t in 0..16u8 {
                let dir = dir.path();
                s.spawn(move || {
                    for round in 0..8u8 {
                        // Every thread also rewrites one shared file: each write must still
                        // succeed, because no two writes share a temporary.
                        let shared = dir.join("shared.bin");
                        write_atomic(&shared, &[t; 4096]).unwrap();
                        let own = dir.join(format!("file-{t}.bin"));
                        write_atomic(&own, &[t, round]).unwrap();
                    }
                });
            }
        });
        let names = entries(dir.path());
        assert_eq!(names.len(), 17, "{names:?}");
        for t in 0..16u8 {
            let own = std::fs::read(dir.path().join(format!("file-{t}.bin"))).unwrap();
            assert_eq!(own, [t, 7]);
        }
        let shared = std::fs::read(dir.path().join("shared.bin")).unwrap();
        assert_eq!(shared.len(), 4096);
        assert!(shared.iter().all(|&b| b == shared[0]), "a torn file");
    }

    #[test]
    fn a_missing_folder_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir
            .path()
            .join("no")
            .join("such")
            .join("folder")
            .join("x.bin");
        let err = write_atomic(&p, b"x").unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::NotFound);
        assert!(entries(dir.path()).is_empty());
    }

    #[test]
    fn a_missing_folder_or_a_file_as_folder_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let err = write_atomic(&dir.path().join("nodir").join("x.bin"), b"x").unwrap_err();
        assert!(err.to_string().ends_with("nodir does not exist"), "{err}");
        let file = dir.path().join("file");
        std::fs::write(&file, b"").unwrap();
        let err = write_atomic(&file.join("x.bin"), b"x").unwrap_err();
        assert!(err.to_string().ends_with("file is not a folder"), "{err}");
    }

    #[cfg(unix)]
    #[test]
    fn a_replaced_file_keeps_its_permissions() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("private.bin");
        for mode in [0o600, 0o444, 0o640] {
            std::fs::write(&p, b"old").unwrap_or_else(|_| {
                // A read-only file from the last round: make it writable to reset it.
                std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o600)).unwrap();
                std::fs::write(&p, b"old").unwrap();
            });
            std::fs::set_permissions(&p, std::fs::Permissions::from_mode(mode)).unwrap();
            write_atomic(&p, b"new").unwrap();
            assert_eq!(std::fs::read(&p).unwrap(), b"new");
            let now = std::fs::metadata(&p).unwrap().permissions().mode() & 0o777;
            assert_eq!(now, mode, "{now:o} against {mode:o}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn links_are_written_through_even_when_they_dangle() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        // A relative link into a folder, a link to that link, and a dangling link.
        std::os::unix::fs::symlink("sub/target.bin", dir.path().join("link.bin")).unwrap();
        std::os::unix::fs::symlink("link.bin", dir.path().join("link2.bin")).unwrap();
        std::fs::write(sub.join("target.bin"), b"old").unwrap();
        write_atomic(&dir.path().join("link2.bin"), b"new").unwrap();
        assert_eq!(std::fs::read(sub.join("target.bin")).unwrap(), b"new");
        for link in ["link.bin", "link2.bin"] {
            let meta = std::fs::symlink_metadata(dir.path().join(link)).unwrap();
            assert!(meta.file_type().is_symlink(), "{link} was replaced");
        }
        std::os::unix::fs::symlink("nowhere.bin", dir.path().join("dangling.bin")).unwrap();
        write_atomic(&dir.path().join("dangling.bin"), b"made").unwrap();
        assert_eq!(
            std::fs::read(dir.path().join("nowhere.bin")).unwrap(),
            b"made"
        );
        let meta = std::fs::symlink_metadata(dir.path().join("dangling.bin")).unwrap();
        assert!(meta.file_type().is_symlink());
        // A loop of links is an error of the write, not a hang.
        std::os::unix::fs::symlink("loop_b", dir.path().join("loop_a")).unwrap();
        std::os::unix::fs::symlink("loop_a", dir.path().join("loop_b")).unwrap();
        write_atomic(&dir.path().join("loop_a"), b"x").unwrap();
        assert_eq!(std::fs::read(dir.path().join("loop_a")).unwrap(), b"x");
    }

    /// A killed writer's temporary is recognised by name and dead process; a live one's (this
    /// process's, or pid 1's) and other names are not.
    #[cfg(target_os = "linux")]
    #[test]
    fn stale_temporaries_are_those_of_writers_gone() {
        // Pids above the kernel's pid_max (4,194,304 at most) are never running.
        let dead = 4_194_305 + u32::from(std::process::id() == 4_194_305);
        assert_eq!(
            stale_temporary_target(&format!(".view_017.png.{dead}.76.tmp")),
            Some("view_017.png")
        );
        assert_eq!(
            stale_temporary_target(&format!(".a.b.c.{dead}.0.tmp")),
            Some("a.b.c")
        );
        let own = format!(".view_017.png.{}.3.tmp", std::process::id());
        assert_eq!(stale_temporary_target(&own), None);
        assert_eq!(stale_temporary_target(".view_017.png.1.3.tmp"), None);
        for other in [
            "view_017.png",
            ".view_017.png.tmp",
            ".view.png.x1.2.tmp",
            ".view.png.12..tmp",
            &format!("..{dead}.1.tmp"),
            &format!(".view.png.{dead}.1.tmp.bak"),
        ] {
            assert_eq!(stale_temporary_target(other), None, "{other}");
        }
        // What this crate writes is what it recognises.
        let dir = tempfile::tempdir().unwrap();
        let temp = temporary_sibling(&dir.path().join("model.ply"));
        let name = temp.file_name().unwrap().to_str().unwrap().to_owned();
        let renamed = name.replacen(&std::process::id().to_string(), &dead.to_string(), 1);
        assert_eq!(stale_temporary_target(&renamed), Some("model.ply"));
    }

    #[test]
    fn temporaries_differ_and_stay_beside_the_target() {
        let p = Path::new("some/dir/model.ply");
        let (a, b) = (temporary_sibling(p), temporary_sibling(p));
        assert_ne!(a, b);
        assert_eq!(a.parent(), p.parent());
        let name = a.file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            name.starts_with(".model.ply.") && name.ends_with(".tmp"),
            "{name}"
        );
    }
}
