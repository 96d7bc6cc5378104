//! Helpers shared by the fuzz targets: readers that only take a path get the fuzzer's bytes
//! through files in one scratch directory per process (under /dev/shm when it exists, so the
//! writes stay in memory).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The scratch directory of this process, created on first use and never removed (libFuzzer
/// ends the process with `exit`, so nothing would run a destructor anyway).
pub fn scratch_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = Path::new("/dev/shm");
        let base = if base.is_dir() {
            base.to_path_buf()
        } else {
            std::env::temp_dir()
        };
        let dir = base.join(format!("transcoder-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("cannot create the fuzz scratch directory");
        dir
    })
}

/// Writes `bytes` to `name` in the scratch directory and returns its path.
pub fn scratch_file(name: &str, bytes: &[u8]) -> PathBuf {
    let path = scratch_dir().join(name);
    std::fs::write(&path, bytes).expect("cannot write the fuzz scratch file");
    path
}

/// plenoptic-io runs `gltf::import` and `tobj::load_obj` inside `catch_unwind` (both have
/// panicked on malformed input) and turns a panic there into `Error::Gltf` / `Error::Obj`.
/// libFuzzer's panic hook aborts on every panic, caught or not, so this hook lets through
/// (silently) only panics whose backtrace has that `catch_unwind` frame; every other panic
/// still goes to libFuzzer's hook and is a crash. cargo-fuzz builds with line-tables-only debug
/// information, where the frame reads `catch_unwind<plenoptic_io::gltf_mesh::read_gltf::…>`.
pub fn allow_caught_reader_panics() {
    let fuzzer_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let trace = std::backtrace::Backtrace::force_capture().to_string();
        let caught = trace.lines().any(|frame| {
            frame.contains("catch_unwind<plenoptic_io::gltf_mesh::read_gltf")
                || frame.contains("catch_unwind<plenoptic_io::obj::read_obj")
        });
        if !caught {
            fuzzer_hook(info);
        }
    }));
}
