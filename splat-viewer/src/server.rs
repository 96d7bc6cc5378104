//! A small static HTTP server for a [`Site`], meant for one person's browser on the same machine.
//!
//! Built on hyper (HTTP/1.1 only) on a single-threaded tokio runtime. hyper is the HTTP
//! implementation under most of the Rust web ecosystem (axum, reqwest), actively maintained, and
//! it bounds what a client can make it hold: the request head is parsed within a fixed buffer
//! (larger heads get 431, malformed ones 400, and the connection is closed), headers have a
//! read timeout. tiny_http, the small alternative, reads header lines without a length limit
//! and has had no release since 2022. Anything hyper leaves to us is here: GET and HEAD only,
//! a cap on open connections, a `Host` check against DNS rebinding, and headers that keep the
//! page to its own files (a content security policy with no outside origin).

use std::convert::Infallible;
use std::future::Future;
use std::net::{SocketAddr, TcpListener};
use std::sync::Arc;
use std::time::Duration;

use std::io::Read;
use std::pin::Pin;
use std::task::{Context, Poll};

use bytes::Bytes;
use hyper::body::{Frame, Incoming, SizeHint};
use hyper::header::{self, HeaderValue};
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::{TokioIo, TokioTimer};

use crate::Error;
use crate::site::{Content, Refusal, Site};

/// Largest request head (request line and headers) read; hyper answers 431 beyond it. Browsers
/// send well under 4 KiB to a local page.
pub const MAX_REQUEST_HEAD: usize = 16 * 1024;
/// Time a client has to send its request head.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// Connections served at once; further ones are closed at once until one ends.
pub const MAX_CONNECTIONS: usize = 64;
/// Longest life of one connection (a slow client cannot hold a slot for ever).
pub const CONNECTION_LIFETIME: Duration = Duration::from_secs(600);

/// Bytes of a file read at a time while a client takes it: what one connection holds of a file.
pub const FILE_CHUNK: usize = 256 * 1024;

/// What the served pages may load: only this server's files, workers from blob: URLs (the
/// viewer's sort worker) and data: images (the report's pictures); nothing from elsewhere.
const CONTENT_SECURITY_POLICY: &str = "default-src 'self'; script-src 'self'; \
     worker-src blob:; img-src 'self' data: blob:; style-src 'self' 'unsafe-inline'; \
     connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'";

/// A bound, not yet running server.
#[derive(Debug)]
pub struct Server {
    listener: TcpListener,
    site: Arc<Site>,
    hosts: Option<Vec<String>>,
}

impl Server {
    /// Binds `addr` (port 0 picks a free port) to serve `site`.
    ///
    /// # Errors
    /// [`Error::Bind`] when the address cannot be bound.
    pub fn bind(addr: SocketAddr, site: Site) -> Result<Self, Error> {
        let listener = TcpListener::bind(addr).map_err(|source| Error::Bind { addr, source })?;
        let local = listener
            .local_addr()
            .map_err(|source| Error::Bind { addr, source })?;
        let hosts = allowed_hosts(local);
        Ok(Self {
            listener,
            site: Arc::new(site),
            hosts,
        })
    }

    /// Returns the address the server listens on.
    ///
    /// # Errors
    /// The socket's error, if its address cannot be read.
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.listener.local_addr()
    }

    /// Serves until `stop` completes.
    ///
    /// # Errors
    /// [`Error::Runtime`] when the runtime or the listener cannot be set up.
    pub fn run_until(self, stop: impl Future<Output = ()>) -> Result<(), Error> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .map_err(Error::Runtime)?;
        rt.block_on(self.accept_loop(stop))
    }

    /// Serves until the process ends.
    ///
    /// # Errors
    /// As [`Server::run_until`].
    pub fn run(self) -> Result<(), Error> {
        self.run_until(std::future::pending())
    }

    async fn accept_loop(self, stop: impl Future<Output = ()>) -> Result<(), Error> {
        self.listener
            .set_nonblocking(true)
            .map_err(Error::Runtime)?;
        let listener = tokio::net::TcpListener::from_std(self.listener).map_err(Error::Runtime)?;
        let slots = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
        let handler = Arc::new(Handler {
            site: self.site,
            hosts: self.hosts,
        });
        let mut stop = std::pin::pin!(stop);
        loop {
            let stream = tokio::select! {
                () = &mut stop => return Ok(()),
                accepted = listener.accept() => match accepted {
                    Ok((stream, _)) => stream,
                    // Out of descriptors or a connection reset before it was accepted: wait a
                    // moment rather than spin, and go on.
                    Err(_) => {
                        tokio::time::sleep(Duration::from_millis(20)).await;
                        continue;
                    }
                },
            };
            let Ok(slot) = slots.clone().try_acquire_owned() else {
                continue; // dropped: closed at once
            };
            let handler = handler.clone();
            tokio::spawn(async move {
                let service = hyper::service::service_fn(move |req| {
                    let handler = handler.clone();
                    async move { Ok::<_, Infallible>(handler.respond(&req)) }
                });
                let connection = hyper::server::conn::http1::Builder::new()
                    .timer(TokioTimer::new())
                    .header_read_timeout(HEADER_TIMEOUT)
                    .max_buf_size(MAX_REQUEST_HEAD)
                    .serve_connection(TokioIo::new(stream), service);
                // Errors of one connection (a malformed request, a client gone) end only it.
                let _ = tokio::time::timeout(CONNECTION_LIFETIME, connection).await;
                drop(slot);
            });
        }
    }
}

/// Answers one request.
#[derive(Debug)]
struct Handler {
    site: Arc<Site>,
    hosts: Option<Vec<String>>,
}

impl Handler {
    fn respond(&self, req: &Request<Incoming>) -> Response<Body> {
        if req.method() != Method::GET && req.method() != Method::HEAD {
            let mut r = plain(StatusCode::METHOD_NOT_ALLOWED, "only GET and HEAD\n");
            r.headers_mut()
                .insert(header::ALLOW, HeaderValue::from_static("GET, HEAD"));
            return r;
        }
        if let Some(hosts) = &self.hosts {
            let host = req
                .headers()
                .get(header::HOST)
                .and_then(|h| h.to_str().ok())
                .map(str::to_ascii_lowercase);
            if !host.is_some_and(|h| hosts.contains(&h)) {
                return plain(StatusCode::FORBIDDEN, "unexpected Host header\n");
            }
        }
        let uri = req.uri();
        // Only origin-form targets ("/path"): this is no proxy.
        if uri.scheme().is_some() || uri.authority().is_some() {
            return plain(StatusCode::BAD_REQUEST, "absolute-form request target\n");
        }
        let target = uri.path_and_query().map_or("/", |p| p.as_str());
        if uri.path() == "/" {
            let mut r = plain(StatusCode::FOUND, "");
            if let Ok(location) = HeaderValue::from_str(&format!("/{}", self.site.entry())) {
                r.headers_mut().insert(header::LOCATION, location);
            }
            return r;
        }
        match self.site.resolve(target) {
            Ok(found) => {
                let mut r = Response::new(Body::from(found.content));
                r.headers_mut().insert(
                    header::CONTENT_TYPE,
                    HeaderValue::from_static(found.content_type),
                );
                secure(r)
            }
            Err(e @ Refusal::Malformed(_)) => plain(StatusCode::BAD_REQUEST, &format!("{e}\n")),
            Err(e @ Refusal::Forbidden(_)) => plain(StatusCode::FORBIDDEN, &format!("{e}\n")),
            // Browsers ask for an icon no page named: "no content" rather than an error.
            Err(Refusal::NotFound) if uri.path() == "/favicon.ico" => {
                plain(StatusCode::NO_CONTENT, "")
            }
            Err(Refusal::NotFound) => plain(StatusCode::NOT_FOUND, "not found\n"),
        }
    }
}

/// A response's body: bytes in memory, or a file read [`FILE_CHUNK`] bytes at a time as hyper
/// sends it, its exact length known up front (the `Content-Length`; a `HEAD` reads nothing). The
/// read blocks the server's one thread for a chunk's time; a file that shrank since it was
/// opened ends the response with an error, so the client sees a cut answer, not a short file.
#[derive(Debug)]
enum Body {
    Memory(Option<Bytes>),
    File { file: std::fs::File, left: u64 },
}

impl From<Content> for Body {
    fn from(content: Content) -> Self {
        match content {
            Content::Memory(bytes) => Self::Memory(Some(bytes)),
            Content::File { file, len } => Self::File { file, left: len },
        }
    }
}

impl hyper::body::Body for Body {
    type Data = Bytes;
    type Error = std::io::Error;

    fn poll_frame(
        self: Pin<&mut Self>,
        _: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, std::io::Error>>> {
        Poll::Ready(match self.get_mut() {
            Self::Memory(bytes) => bytes
                .take()
                .filter(|b| !b.is_empty())
                .map(|b| Ok(Frame::data(b))),
            Self::File { file, left } => (*left > 0).then(|| {
                let n = usize::try_from(*left).map_or(FILE_CHUNK, |left| left.min(FILE_CHUNK));
                let mut chunk = vec![0; n];
                file.read_exact(&mut chunk)?;
                *left -= n as u64;
                Ok(Frame::data(Bytes::from(chunk)))
            }),
        })
    }

    fn is_end_stream(&self) -> bool {
        match self {
            Self::Memory(bytes) => bytes.as_ref().is_none_or(Bytes::is_empty),
            Self::File { left, .. } => *left == 0,
        }
    }

    fn size_hint(&self) -> SizeHint {
        SizeHint::with_exact(match self {
            Self::Memory(bytes) => bytes.as_ref().map_or(0, |b| b.len() as u64),
            Self::File { left, .. } => *left,
        })
    }
}

/// A plain-text response with `status`.
fn plain(status: StatusCode, text: &str) -> Response<Body> {
    let mut r = Response::new(Body::Memory(Some(Bytes::from(text.to_string()))));
    *r.status_mut() = status;
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; charset=utf-8"),
    );
    secure(r)
}

/// Adds the headers every response carries.
fn secure(mut r: Response<Body>) -> Response<Body> {
    let h = r.headers_mut();
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CONTENT_SECURITY_POLICY),
    );
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    r
}

/// The `Host` values a server listening on `local` answers: on a loopback address only local
/// names, so a page elsewhere cannot reach it through a DNS name rebound to 127.0.0.1; `None`
/// (any) elsewhere. On port 80 also the names alone, as browsers leave HTTP's default port out.
fn allowed_hosts(local: SocketAddr) -> Option<Vec<String>> {
    local.ip().is_loopback().then(|| {
        let port = local.port();
        let names = [
            "127.0.0.1".to_owned(),
            "localhost".to_owned(),
            "[::1]".to_owned(),
            match local {
                SocketAddr::V4(a) => a.ip().to_string(),
                SocketAddr::V6(a) => format!("[{}]", a.ip()),
            },
        ];
        let mut hosts: Vec<String> = names.iter().map(|n| format!("{n}:{port}")).collect();
        if port == 80 {
            hosts.extend(names);
        }
        hosts
    })
}

#[cfg(test)]
mod host_tests {
    use super::*;

    #[test]
    fn loopback_servers_answer_local_names_and_port_80_the_names_alone() {
        let on = |s: &str| allowed_hosts(s.parse().unwrap());
        let hosts = on("127.0.0.1:8080").unwrap();
        assert!(hosts.contains(&"localhost:8080".to_owned()));
        assert!(!hosts.contains(&"localhost".to_owned()));
        let hosts = on("127.0.0.1:80").unwrap();
        for h in ["localhost", "127.0.0.1", "[::1]", "localhost:80"] {
            assert!(hosts.contains(&h.to_owned()), "{h}");
        }
        assert!(on("[::1]:80").unwrap().contains(&"[::1]".to_owned()));
        assert_eq!(on("0.0.0.0:80"), None);
    }
}

#[cfg(test)]
mod streaming_tests {
    use std::io::Write;
    use std::net::TcpStream;

    use http_body_util::BodyExt;

    use super::*;

    /// One request over a fresh connection: the response's head and body.
    fn request(addr: SocketAddr, method: &str, path: &str) -> (String, Vec<u8>) {
        let mut stream = TcpStream::connect(addr).expect("connects");
        write!(
            stream,
            "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
        )
        .expect("sends");
        let mut answer = Vec::new();
        stream.read_to_end(&mut answer).expect("reads");
        let split = answer
            .windows(4)
            .position(|w| w == b"\r\n\r\n")
            .expect("a head");
        let head = String::from_utf8_lossy(&answer[..split]).to_ascii_lowercase();
        (head, answer[split + 4..].to_vec())
    }

    /// A file several chunks long (and not a whole number of them) comes back whole with its
    /// length announced; a HEAD gets the length and no body.
    #[test]
    fn files_are_streamed_whole_with_their_length() {
        let dir = tempfile::tempdir().unwrap();
        let big: Vec<u8> = (0..FILE_CHUNK * 3 + 1234)
            .map(|i| (i * 7 % 251) as u8)
            .collect();
        std::fs::write(dir.path().join("model.ply"), &big).unwrap();
        std::fs::write(dir.path().join("empty.txt"), b"").unwrap();
        let site = Site::new("model.ply").with_root(dir.path()).unwrap();
        let server = Server::bind("127.0.0.1:0".parse().unwrap(), site).unwrap();
        let addr = server.local_addr().unwrap();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let serving = std::thread::spawn(move || {
            server.run_until(async move {
                let _ = stopped.await;
            })
        });
        let (head, body) = request(addr, "GET", "/model.ply");
        assert!(head.starts_with("http/1.1 200"), "{head}");
        assert!(
            head.contains(&format!("content-length: {}", big.len())),
            "{head}"
        );
        assert!(body == big, "{} bytes back of {}", body.len(), big.len());
        let (head, body) = request(addr, "HEAD", "/model.ply");
        assert!(
            head.contains(&format!("content-length: {}", big.len())),
            "{head}"
        );
        assert!(body.is_empty());
        let (head, body) = request(addr, "GET", "/empty.txt");
        assert!(head.contains("content-length: 0"), "{head}");
        assert!(body.is_empty());
        stop.send(()).unwrap();
        serving.join().unwrap().unwrap();
    }

    /// A file cut shorter after it was opened ends its body with an error, never a short body
    /// that looks whole.
    #[test]
    fn a_file_cut_while_served_ends_in_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.bin");
        std::fs::write(&path, vec![1u8; FILE_CHUNK + 10]).unwrap();
        let file = std::fs::File::open(&path).unwrap();
        let len = file.metadata().unwrap().len();
        std::fs::OpenOptions::new()
            .write(true)
            .open(&path)
            .unwrap()
            .set_len(100)
            .unwrap();
        let body = Body::from(Content::File { file, len });
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        let collected = rt.block_on(body.collect());
        let err = collected.expect_err("a cut file is an error");
        assert_eq!(err.kind(), std::io::ErrorKind::UnexpectedEof);
    }
}
