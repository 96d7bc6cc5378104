//! The server over real sockets: it serves its folder and nothing outside it, and survives
//! malformed and oversized requests (each followed by a request that must still be answered).

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::time::Duration;

use splat_viewer::{Server, Site};

struct Running {
    addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Running {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(t) = self.thread.take() {
            t.join().unwrap();
        }
    }
}

fn start(site: Site) -> Running {
    let server = Server::bind("127.0.0.1:0".parse().unwrap(), site).unwrap();
    let addr = server.local_addr().unwrap();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let thread = std::thread::spawn(move || {
        server
            .run_until(async {
                let _ = rx.await;
            })
            .unwrap();
    });
    Running {
        addr,
        stop: Some(tx),
        thread: Some(thread),
    }
}

/// Sends raw bytes and returns what comes back until the server closes (or 5 s pass). Write
/// errors are ignored: the server may close before reading everything.
fn raw(addr: SocketAddr, request: &[u8]) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    s.set_write_timeout(Some(Duration::from_secs(5))).unwrap();
    let _ = s.write_all(request);
    let mut out = Vec::new();
    let mut buf = [0u8; 8192];
    loop {
        match s.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => out.extend_from_slice(&buf[..n]),
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn get(addr: SocketAddr, target: &str) -> String {
    raw(
        addr,
        format!("GET {target} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes(),
    )
}

fn status(response: &str) -> u16 {
    response
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0)
}

/// A root with a page and a sub-folder, and beside it a secret the server must never give out.
fn fixture(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let root = dir.join("root");
    let outside = dir.join("outside");
    std::fs::create_dir_all(root.join("sub")).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::write(root.join("page.html"), "<p>page</p>").unwrap();
    std::fs::write(root.join("sub/data.txt"), "data").unwrap();
    std::fs::write(outside.join("secret.txt"), "TOP-SECRET").unwrap();
    std::fs::write(dir.join("secret.txt"), "TOP-SECRET").unwrap();
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(outside.join("secret.txt"), root.join("link.txt")).unwrap();
        std::os::unix::fs::symlink(&outside, root.join("linkdir")).unwrap();
    }
    (root, outside)
}

fn assert_still_serving(addr: SocketAddr) {
    let r = get(addr, "/page.html");
    assert_eq!(status(&r), 200, "{r}");
    assert!(r.ends_with("<p>page</p>"), "{r}");
}

#[test]
fn serves_files_with_their_type_and_a_strict_policy() {
    let dir = tempfile::tempdir().unwrap();
    let (root, _) = fixture(dir.path());
    let running = start(Site::new("page.html").with_root(&root).unwrap());
    let r = get(running.addr, "/sub/data.txt");
    assert_eq!(status(&r), 200, "{r}");
    assert!(r.ends_with("data"));
    let lower = r.to_ascii_lowercase();
    assert!(lower.contains("content-type: text/plain"), "{r}");
    assert!(
        lower.contains("content-security-policy: default-src 'self'"),
        "{r}"
    );
    assert!(lower.contains("x-content-type-options: nosniff"), "{r}");
    // "/" sends the browser to the entry page.
    let r = get(running.addr, "/");
    assert_eq!(status(&r), 302, "{r}");
    assert!(
        r.to_ascii_lowercase().contains("location: /page.html"),
        "{r}"
    );
    assert_eq!(status(&get(running.addr, "/missing.html")), 404);
    assert_eq!(status(&get(running.addr, "/favicon.ico")), 204);
    // HEAD has the headers and no body; other methods are refused.
    let r = raw(
        running.addr,
        format!(
            "HEAD /page.html HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            running.addr
        )
        .as_bytes(),
    );
    assert_eq!(status(&r), 200, "{r}");
    assert!(!r.contains("<p>page</p>"), "{r}");
    let r = raw(
        running.addr,
        format!(
            "POST /page.html HTTP/1.1\r\nHost: {}\r\nContent-Length: 3\r\nConnection: close\r\n\r\nabc",
            running.addr
        )
        .as_bytes(),
    );
    assert_eq!(status(&r), 405, "{r}");
}

#[test]
fn refuses_every_way_out_of_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let (root, outside) = fixture(dir.path());
    let running = start(Site::new("page.html").with_root(&root).unwrap());
    let absolute = outside.join("secret.txt").display().to_string();
    let mut attempts = vec![
        "/../secret.txt".to_string(),
        "/../outside/secret.txt".to_string(),
        "/sub/../../secret.txt".to_string(),
        "/%2e%2e/secret.txt".to_string(),
        "/%2E%2E/outside/secret.txt".to_string(),
        "/.%2e/secret.txt".to_string(),
        "/%2e%2e%2fsecret.txt".to_string(),
        "/..%2F..%2Fsecret.txt".to_string(),
        "/..%5csecret.txt".to_string(),
        "/%252e%252e/secret.txt".to_string(),
        "//secret.txt".to_string(),
        format!("/{absolute}"),
        format!("/{}", absolute.replace('/', "%2F")),
        absolute.clone(),
        format!("http://{}/../secret.txt", running.addr),
        "/link.txt".to_string(),
        "/linkdir/secret.txt".to_string(),
    ];
    attempts.push(format!("/%2F{}", absolute.trim_start_matches('/')));
    for target in &attempts {
        let r = get(running.addr, target);
        let code = status(&r);
        assert!(
            matches!(code, 400 | 403 | 404),
            "{target}: status {code}\n{r}"
        );
        assert!(!r.contains("TOP-SECRET"), "{target} leaked the file:\n{r}");
    }
    // The symlinks out are refused as such, not merely missed.
    assert_eq!(status(&get(running.addr, "/link.txt")), 403);
    assert_eq!(status(&get(running.addr, "/%2e%2e/secret.txt")), 403);
    assert_still_serving(running.addr);
}

#[test]
fn survives_malformed_and_oversized_requests() {
    let dir = tempfile::tempdir().unwrap();
    let (root, _) = fixture(dir.path());
    let running = start(Site::new("page.html").with_root(&root).unwrap());
    let addr = running.addr;
    let long_path = format!(
        "GET /{} HTTP/1.1\r\nHost: {addr}\r\n\r\n",
        "a".repeat(100_000)
    );
    let big_header = format!(
        "GET /page.html HTTP/1.1\r\nHost: {addr}\r\nX-Big: {}\r\n\r\n",
        "b".repeat(1 << 20)
    );
    let many_headers = format!(
        "GET /page.html HTTP/1.1\r\nHost: {addr}\r\n{}\r\n",
        (0..2000)
            .map(|i| format!("X-{i}: v\r\n"))
            .collect::<String>()
    );
    let endless_line = vec![b'G'; 4 << 20];
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("garbage", b"\x00\x01\x02\xff garbage \r\n\r\n".to_vec()),
        ("no version", b"GET /page.html\r\n\r\n".to_vec()),
        ("bad version", b"GET /page.html HTTP/9.9\r\n\r\n".to_vec()),
        (
            "bad header",
            format!("GET /page.html HTTP/1.1\r\nHost: {addr}\r\nno colon here\r\n\r\n")
                .into_bytes(),
        ),
        (
            "invalid utf-8 path",
            format!("GET /\u{fffd}%ff%fe HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n")
                .into_bytes(),
        ),
        (
            "bad escape",
            format!("GET /%zz HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").into_bytes(),
        ),
        ("long path", long_path.into_bytes()),
        ("big header", big_header.into_bytes()),
        ("many headers", many_headers.into_bytes()),
        ("endless request line", endless_line),
        (
            "huge declared body",
            format!(
                "GET /page.html HTTP/1.1\r\nHost: {addr}\r\nContent-Length: 99999999999\r\n\r\nxx"
            )
            .into_bytes(),
        ),
        (
            "half a request",
            format!("GET /page.html HTTP/1.1\r\nHost: {addr}\r\n").into_bytes(),
        ),
    ];
    for (what, request) in cases {
        let r = raw(addr, &request);
        let code = status(&r);
        assert!(
            code == 0 || (400..500).contains(&code) || code == 200,
            "{what}: status {code}"
        );
        if what.contains("big") || what.contains("long") || what.contains("many") {
            assert!(
                matches!(code, 0 | 400 | 413 | 414 | 431),
                "{what}: status {code}"
            );
        }
        assert_still_serving(addr);
    }
}

#[test]
fn refuses_foreign_host_headers_on_loopback() {
    let dir = tempfile::tempdir().unwrap();
    let (root, _) = fixture(dir.path());
    let running = start(Site::new("page.html").with_root(&root).unwrap());
    // A page elsewhere reaching the server through a DNS name rebound to 127.0.0.1.
    let r = raw(
        running.addr,
        b"GET /page.html HTTP/1.1\r\nHost: attacker.example\r\nConnection: close\r\n\r\n",
    );
    assert_eq!(status(&r), 403, "{r}");
    let r = raw(
        running.addr,
        format!(
            "GET /page.html HTTP/1.1\r\nHost: localhost:{}\r\nConnection: close\r\n\r\n",
            running.addr.port()
        )
        .as_bytes(),
    );
    assert_eq!(status(&r), 200, "{r}");
}

#[test]
fn a_model_site_serves_the_viewer_and_the_model_only() {
    let site = splat_viewer::model_site("m", "model.ply", b"ply\n".to_vec(), Vec::new()).unwrap();
    let running = start(site);
    for (target, needle) in [
        ("/index.html", "viewer.js"),
        ("/viewer.js", "VIEWER_SOURCES"),
        ("/scene.js", "\"file\":\"model.ply\""),
        ("/model.ply", "ply"),
    ] {
        let r = get(running.addr, target);
        assert_eq!(status(&r), 200, "{target}: {r}");
        assert!(r.contains(needle), "{target}: {r}");
    }
    assert_eq!(status(&get(running.addr, "/Cargo.toml")), 404);
    assert_eq!(status(&get(running.addr, "/../Cargo.toml")), 403);
}
