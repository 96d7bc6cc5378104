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

use bytes::Bytes;
use http_body_util::Full;
use hyper::body::Incoming;
use hyper::header::{self, HeaderValue};
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::{TokioIo, TokioTimer};

use crate::Error;
use crate::site::{Refusal, Site};

/// Largest request head (request line and headers) read; hyper answers 431 beyond it. Browsers
/// send well under 4 KiB to a local page.
pub const MAX_REQUEST_HEAD: usize = 16 * 1024;
/// Time a client has to send its request head.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// Connections served at once; further ones are closed at once until one ends.
pub const MAX_CONNECTIONS: usize = 64;
/// Longest life of one connection (a slow client cannot hold a slot for ever).
pub const CONNECTION_LIFETIME: Duration = Duration::from_secs(600);

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
    fn respond(&self, req: &Request<Incoming>) -> Response<Full<Bytes>> {
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
                let mut r = Response::new(Full::new(found.bytes));
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

/// A plain-text response with `status`.
fn plain(status: StatusCode, text: &str) -> Response<Full<Bytes>> {
    let mut r = Response::new(Full::new(Bytes::from(text.to_string())));
    *r.status_mut() = status;
    r.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; charset=utf-8"),
    );
    secure(r)
}

/// Adds the headers every response carries.
fn secure(mut r: Response<Full<Bytes>>) -> Response<Full<Bytes>> {
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
