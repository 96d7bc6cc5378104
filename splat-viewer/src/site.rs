//! What the viewer's server may hand out: files in memory (the viewer's assets, a model) and the
//! regular files under one root folder, and the one decision of which file a request names.
//!
//! A request path is untrusted. It is split on `/` before percent-decoding, so an encoded `%2F`
//! cannot join segments; every segment is decoded strictly and refused when it is `.` or `..`
//! (plain or encoded: browsers remove dot segments before sending, so only a crafted request
//! has one), empty in the middle (`//etc`, an absolute path), holds a `/`, `\`, `:` or NUL once
//! decoded, or starts with a dot (hidden files such as `.git`). What is left is joined under the
//! root and resolved with every symlink followed; a file whose real path is not under the root's
//! real path is refused, so a symlink cannot lead out of the folder.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use bytes::Bytes;

use crate::Error;

/// A file the site holds in memory.
#[derive(Clone, Debug)]
struct MemoryFile {
    bytes: Bytes,
    content_type: &'static str,
}

/// The files a server hands out: in-memory files first, then files under an optional root.
#[derive(Clone, Debug, Default)]
pub struct Site {
    root: Option<PathBuf>,
    memory: BTreeMap<String, MemoryFile>,
    entry: String,
}

/// Why a request path names no file that may be served.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// The path is not a well-formed origin-form path (bad percent escape, not UTF-8, no leading
    /// `/`, an empty segment).
    #[error("malformed path: {0}")]
    Malformed(&'static str),
    /// The path tries to leave the served folder or names a hidden or special file.
    #[error("forbidden path: {0}")]
    Forbidden(&'static str),
    /// No file there.
    #[error("not found")]
    NotFound,
}

/// A file found for a request.
#[derive(Debug)]
pub struct Found {
    /// Its content.
    pub content: Content,
    /// Its media type.
    pub content_type: &'static str,
}

/// What a found file holds: bytes in memory, or a file under the root opened for the request and
/// read a chunk at a time as the client takes it, so serving a large model holds no copy of it.
#[derive(Debug)]
pub enum Content {
    /// In memory (the viewer's assets, a model named on the command line).
    Memory(Bytes),
    /// An open regular file and its length when opened.
    File {
        /// The file, read from its start.
        file: std::fs::File,
        /// Its length in bytes when it was opened.
        len: u64,
    },
}

impl Content {
    /// Its length in bytes.
    #[must_use]
    pub fn len(&self) -> u64 {
        match self {
            Self::Memory(bytes) => bytes.len() as u64,
            Self::File { len, .. } => *len,
        }
    }

    /// Whether it holds no bytes.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Reads it whole (for tests and small files).
    ///
    /// # Errors
    /// The file's read error; a file that shrank since it was opened is `UnexpectedEof`.
    pub fn read_all(self) -> std::io::Result<Bytes> {
        match self {
            Self::Memory(bytes) => Ok(bytes),
            Self::File { mut file, len } => {
                let mut buf = vec![0; usize::try_from(len).unwrap_or(usize::MAX)];
                std::io::Read::read_exact(&mut file, &mut buf)?;
                Ok(buf.into())
            }
        }
    }
}

impl Site {
    /// Returns a site with no files; `entry` is the path (without the leading `/`) that `/`
    /// redirects to.
    #[must_use]
    pub fn new(entry: impl Into<String>) -> Self {
        Self {
            entry: entry.into(),
            ..Self::default()
        }
    }

    /// Serves the regular files under `dir` (after the in-memory files).
    ///
    /// # Errors
    /// [`Error::NotAFolder`] when `dir` is not a folder, [`Error::Io`] when its real path cannot
    /// be resolved.
    pub fn with_root(mut self, dir: &Path) -> Result<Self, Error> {
        let root = dir.canonicalize().map_err(|e| Error::io(dir, e))?;
        if !root.is_dir() {
            return Err(Error::NotAFolder(dir.to_path_buf()));
        }
        self.root = Some(root);
        Ok(self)
    }

    /// Adds an in-memory file at `path` (relative, `/`-separated), its media type taken from
    /// its extension.
    pub fn add(&mut self, path: &str, bytes: impl Into<Bytes>) {
        self.memory.insert(
            path.to_string(),
            MemoryFile {
                bytes: bytes.into(),
                content_type: content_type(path),
            },
        );
    }

    /// Returns the path, without its leading `/`, that a request for `/` is sent to.
    #[must_use]
    pub fn entry(&self) -> &str {
        &self.entry
    }

    /// Returns the file that the request path `target` (origin form, query allowed) names.
    ///
    /// # Errors
    /// A [`Refusal`] saying why nothing is served.
    pub fn resolve(&self, target: &str) -> Result<Found, Refusal> {
        let relative = relative_path(target)?;
        let key = relative.join("/");
        if let Some(f) = self.memory.get(&key) {
            return Ok(Found {
                content: Content::Memory(f.bytes.clone()),
                content_type: f.content_type,
            });
        }
        let root = self.root.as_ref().ok_or(Refusal::NotFound)?;
        let mut path = root.clone();
        path.extend(&relative);
        // Real path, every symlink followed: it must still be under the root's real path.
        let real = path.canonicalize().map_err(|_| Refusal::NotFound)?;
        if !real.starts_with(root) {
            return Err(Refusal::Forbidden("a link that leads out of the folder"));
        }
        let (real, key) = if real.is_dir() {
            // The folder's page is a path of its own: a link there must stay inside too.
            let page = real
                .join("index.html")
                .canonicalize()
                .map_err(|_| Refusal::NotFound)?;
            if !page.starts_with(root) {
                return Err(Refusal::Forbidden("a link that leads out of the folder"));
            }
            (page, format!("{key}/index.html"))
        } else {
            (real, key)
        };
        // Checked before it is opened: opening a named pipe would wait for a writer.
        if !real.is_file() {
            return Err(Refusal::NotFound);
        }
        // Opened, not read: the server streams it (see `Content::File`).
        let file = std::fs::File::open(&real).map_err(|_| Refusal::NotFound)?;
        let meta = file.metadata().map_err(|_| Refusal::NotFound)?;
        if !meta.is_file() {
            return Err(Refusal::NotFound);
        }
        Ok(Found {
            content: Content::File {
                file,
                len: meta.len(),
            },
            content_type: content_type(&key),
        })
    }
}

/// The decoded segments of a request path, each checked (see the module documentation).
fn relative_path(target: &str) -> Result<Vec<String>, Refusal> {
    let path = target.split(['?', '#']).next().unwrap_or_default();
    let Some(rest) = path.strip_prefix('/') else {
        return Err(Refusal::Malformed("the path does not start with /"));
    };
    let raw: Vec<&str> = rest.split('/').collect();
    let mut segments = Vec::with_capacity(raw.len());
    for (i, seg) in raw.iter().enumerate() {
        if seg.is_empty() {
            // Only the last segment may be empty: "/" or "dir/" (its index.html).
            if i + 1 == raw.len() {
                continue;
            }
            return Err(Refusal::Malformed("an empty segment (an absolute path)"));
        }
        let decoded = percent_decode(seg)?;
        if decoded == "." || decoded == ".." {
            return Err(Refusal::Forbidden("a dot segment"));
        }
        if decoded.starts_with('.') {
            return Err(Refusal::Forbidden("a hidden file"));
        }
        if decoded.contains(['/', '\\', ':', '\0']) {
            return Err(Refusal::Forbidden("a separator or drive in a segment"));
        }
        segments.push(decoded);
    }
    Ok(segments)
}

/// Decodes `%XX` escapes; a truncated or non-hex escape, or bytes that are not UTF-8, are refused.
fn percent_decode(s: &str) -> Result<String, Refusal> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = |b: Option<&u8>| b.and_then(|b| (*b as char).to_digit(16));
            match (hex(bytes.get(i + 1)), hex(bytes.get(i + 2))) {
                (Some(hi), Some(lo)) => out.push((hi * 16 + lo) as u8),
                _ => return Err(Refusal::Malformed("a bad percent escape")),
            }
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| Refusal::Malformed("a path that is not UTF-8"))
}

/// The media type of a file from its extension.
#[must_use]
pub fn content_type(path: &str) -> &'static str {
    let ext = path.rsplit_once('.').map_or("", |(_, e)| e);
    match ext.to_ascii_lowercase().as_str() {
        "html" | "htm" => "text/html; charset=utf-8",
        "js" => "text/javascript; charset=utf-8",
        "css" => "text/css; charset=utf-8",
        "json" => "application/json",
        "txt" | "md" | "glsl" | "vert" | "frag" => "text/plain; charset=utf-8",
        "png" => "image/png",
        "jpg" | "jpeg" => "image/jpeg",
        "svg" => "image/svg+xml",
        _ => "application/octet-stream",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A found file's bytes.
    fn body(found: Found) -> Vec<u8> {
        found.content.read_all().expect("readable").to_vec()
    }

    fn site_with(dir: &Path) -> Site {
        let mut s = Site::new("index.html").with_root(dir).unwrap();
        s.add("viewer.js", "let a;");
        s
    }

    #[test]
    fn serves_memory_files_then_files_under_the_root() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(dir.path().join("sub/a b.png"), b"png").unwrap();
        std::fs::write(dir.path().join("sub/index.html"), b"<p>").unwrap();
        let s = site_with(dir.path());
        let f = s.resolve("/viewer.js?v=1").unwrap();
        assert_eq!(f.content_type, "text/javascript; charset=utf-8");
        assert_eq!(body(f), b"let a;");
        let f = s.resolve("/sub/a%20b.png").unwrap();
        assert_eq!((f.content.len(), f.content_type), (3, "image/png"));
        assert_eq!(body(f), b"png");
        assert_eq!(body(s.resolve("/sub/").unwrap()), b"<p>");
        assert_eq!(s.resolve("/sub/none.png").unwrap_err(), Refusal::NotFound);
    }

    #[test]
    fn refuses_dot_segments_plain_and_encoded() {
        let dir = tempfile::tempdir().unwrap();
        let s = site_with(dir.path());
        for bad in [
            "/../etc/passwd",
            "/sub/../../etc/passwd",
            "/%2e%2e/etc/passwd",
            "/%2E%2E/etc/passwd",
            "/.%2e/etc/passwd",
            "/./viewer.js",
            "/%2e/viewer.js",
            "/.git/config",
            "/..%2fetc%2fpasswd",
            "/..%5cetc%5cpasswd",
            "/C:%5cWindows",
        ] {
            assert!(
                matches!(s.resolve(bad), Err(Refusal::Forbidden(_))),
                "{bad}: {:?}",
                s.resolve(bad).map(body)
            );
        }
    }

    #[test]
    fn refuses_absolute_and_malformed_paths() {
        let dir = tempfile::tempdir().unwrap();
        let s = site_with(dir.path());
        for bad in [
            "//etc/passwd",
            "etc/passwd",
            "http://example.invalid/etc/passwd",
            "/a//b",
            "/%zz",
            "/%2",
            "/%ff%fe",
        ] {
            assert!(
                matches!(s.resolve(bad), Err(Refusal::Malformed(_))),
                "{bad}: {:?}",
                s.resolve(bad).map(body)
            );
        }
        // An encoded slash stays inside its segment: it cannot make an absolute path.
        assert!(matches!(
            s.resolve("/%2Fetc%2Fpasswd"),
            Err(Refusal::Forbidden(_))
        ));
    }

    #[cfg(unix)]
    #[test]
    fn refuses_symlinks_that_lead_out_of_the_root() {
        let outside = tempfile::tempdir().unwrap();
        std::fs::write(outside.path().join("secret.txt"), b"secret").unwrap();
        let dir = tempfile::tempdir().unwrap();
        std::os::unix::fs::symlink(outside.path().join("secret.txt"), dir.path().join("s.txt"))
            .unwrap();
        std::os::unix::fs::symlink(outside.path(), dir.path().join("out")).unwrap();
        std::fs::write(dir.path().join("in.txt"), b"in").unwrap();
        std::os::unix::fs::symlink(dir.path().join("in.txt"), dir.path().join("link.txt")).unwrap();
        let s = site_with(dir.path());
        for bad in ["/s.txt", "/out/secret.txt"] {
            assert!(
                matches!(s.resolve(bad), Err(Refusal::Forbidden(_))),
                "{bad}"
            );
        }
        // A link that stays inside is followed.
        assert_eq!(body(s.resolve("/link.txt").unwrap()), b"in");
        // A folder's index.html that is a link out (it was served, as application/octet-stream).
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        std::os::unix::fs::symlink(outside.path().join("secret.txt"), sub.join("index.html"))
            .unwrap();
        for bad in ["/sub", "/sub/"] {
            assert!(
                matches!(s.resolve(bad), Err(Refusal::Forbidden(_))),
                "{bad}"
            );
        }
        // A folder's own index.html is served as HTML.
        let page = dir.path().join("page");
        std::fs::create_dir(&page).unwrap();
        std::fs::write(page.join("index.html"), b"<p>").unwrap();
        let found = s.resolve("/page/").unwrap();
        assert_eq!(found.content_type, "text/html; charset=utf-8");
        assert_eq!(body(found), b"<p>");
    }
}
