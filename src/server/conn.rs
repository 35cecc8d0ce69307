//! Serving HTTP/1.1 connections with hyper directly (`axum::serve` does not expose hyper's
//! connection settings):
//! - a header-read timeout: a client must send a request's headers within it — the first
//!   request's and, on a kept-alive connection, each next one's from when it starts waiting, so
//!   an idle kept-alive connection is closed after it too. A slow-header client (slowloris) is
//!   disconnected instead of holding a connection and a task forever; the request timeout only
//!   starts once the headers are in;
//! - hyper's own refusals — a request line or header it cannot parse (400), a URI over 64 KiB
//!   (414), headers over its buffer (431) — answered as problem documents like every other
//!   refusal: hyper writes those answers itself, without calling the service, with an empty body;
//!   [`Refusals`] rewrites them on the way out;
//! - a connection limit: at most `max_connections` open at once; past it the server stops
//!   accepting (new clients wait in the listener's backlog) until one closes, so a flood of
//!   connections cannot exhaust the process's file descriptors, and with the header timeout a
//!   slowloris holds a slot for that long at most;
//! - a bounded shutdown: on the signal the listener is closed and every connection told to finish
//!   the request in flight and close; at the deadline the rest are dropped.

use std::future::Future;
use std::io;
use std::pin::{Pin, pin};
use std::sync::Arc;
use std::task::{Context, Poll, ready};
use std::time::Duration;

use axum::Router;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, watch};
use tokio::task::JoinSet;

use crate::http::{Problem, error::PROBLEM_JSON};

/// The connections' settings.
#[derive(Clone, Copy, Debug)]
pub struct ConnLimits {
    /// How long a client may take to send a request's headers.
    pub header_timeout: Duration,
    /// Most connections open at once (at least 1).
    pub max_connections: usize,
}

/// Accept and serve connections until `shutdown` resolves; then stop accepting, let requests in
/// flight finish until `deadline()` (called when the shutdown begins) and drop what is left.
/// Returns once every connection is gone.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnLimits,
    shutdown: impl Future<Output = ()>,
    deadline: impl FnOnce() -> tokio::time::Instant,
) {
    let mut conns = JoinSet::new();
    let (closing_tx, closing) = watch::channel(false);
    let mut shutdown = pin!(shutdown);
    let slots = Arc::new(Semaphore::new(limits.max_connections.max(1)));
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            (slot, accepted) = accept(&listener, &slots, limits.max_connections) => match accepted {
                Ok((stream, _)) => {
                    let _ = stream.set_nodelay(true);
                    let served = connection(stream, app.clone(), limits, closing.clone());
                    conns.spawn(async move {
                        served.await;
                        drop(slot);
                    });
                }
                // Out of file descriptors or the like: wait a moment rather than spin.
                Err(e) if !is_connection_error(&e) => {
                    tracing::warn!(error = %e, "accepting a connection");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
                Err(_) => {}
            },
            Some(_) = conns.join_next(), if !conns.is_empty() => {}
        }
    }
    drop(listener);
    let deadline = deadline();
    let _ = closing_tx.send(true);
    let open = conns.len();
    let finished = tokio::time::timeout_at(deadline, async { while conns.join_next().await.is_some() {} }).await;
    if finished.is_err() {
        tracing::warn!(open, left = conns.len(), "shutdown: connections still open at the deadline were dropped");
        conns.abort_all();
        while conns.join_next().await.is_some() {}
    }
}

/// A free connection slot (waited for when every one is taken), then the next connection.
async fn accept(
    listener: &TcpListener,
    slots: &Arc<Semaphore>,
    max: usize,
) -> (OwnedSemaphorePermit, io::Result<(TcpStream, std::net::SocketAddr)>) {
    let slot = match slots.clone().try_acquire_owned() {
        Ok(s) => s,
        Err(_) => {
            tracing::warn!(max_connections = max, "connection limit reached: new connections wait until one closes");
            slots.clone().acquire_owned().await.expect("the semaphore is never closed")
        }
    };
    (slot, listener.accept().await)
}

/// Errors of one connection's accept that say nothing about the listener.
fn is_connection_error(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::ConnectionRefused | io::ErrorKind::ConnectionAborted | io::ErrorKind::ConnectionReset
    )
}

async fn connection(stream: TcpStream, app: Router, limits: ConnLimits, mut closing: watch::Receiver<bool>) {
    let io = TokioIo::new(Refusals::new(stream));
    let service = TowerToHyperService::new(app);
    let mut builder = http1::Builder::new();
    builder.timer(TokioTimer::new()).header_read_timeout(limits.header_timeout).keep_alive(true);
    let mut conn = pin!(builder.serve_connection(io, service));
    let mut told = false;
    loop {
        tokio::select! {
            r = conn.as_mut() => {
                if let Err(e) = r {
                    tracing::debug!(error = %e, "connection ended with an error");
                }
                return;
            }
            _ = closing.wait_for(|c| *c), if !told => {
                told = true;
                conn.as_mut().graceful_shutdown();
            }
        }
    }
}

/// A connection's stream, passing everything through except hyper's own refusals (see
/// [`problem_for`]), which it replaces with a problem document.
pub struct Refusals<S> {
    inner: S,
    /// A replacement being written: its bytes, how many are out, and the length hyper wrote.
    pending: Option<(Vec<u8>, usize, usize)>,
}

impl<S> Refusals<S> {
    pub fn new(inner: S) -> Self {
        Refusals { inner, pending: None }
    }
}

impl<S: AsyncWrite + Unpin> Refusals<S> {
    /// Write the pending replacement out; then report hyper's bytes as written.
    fn poll_pending(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<usize>> {
        let Some((bytes, out, claimed)) = self.pending.as_mut() else { unreachable!("called with a replacement") };
        while *out < bytes.len() {
            let n = ready!(Pin::new(&mut self.inner).poll_write(cx, &bytes[*out..]))?;
            if n == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            *out += n;
        }
        let claimed = *claimed;
        self.pending = None;
        Poll::Ready(Ok(claimed))
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Refusals<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Refusals<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        if self.pending.is_none()
            && let Some(rewritten) = problem_for(buf)
        {
            self.pending = Some((rewritten, 0, buf.len()));
        }
        if self.pending.is_some() {
            return self.poll_pending(cx);
        }
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        if self.pending.is_none() {
            let total: usize = bufs.iter().map(|b| b.len()).sum();
            let first = bufs.iter().find(|b| !b.is_empty());
            if total <= MAX_REFUSAL && first.is_some_and(|b| b.starts_with(b"HTTP/1.1 4")) {
                let whole: Vec<u8> = bufs.iter().flat_map(|b| b.iter().copied()).collect();
                if let Some(rewritten) = problem_for(&whole) {
                    self.pending = Some((rewritten, 0, total));
                }
            }
        }
        if self.pending.is_some() {
            return self.poll_pending(cx);
        }
        Pin::new(&mut self.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        if self.pending.is_some() {
            ready!(self.poll_pending(cx))?;
        }
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        if self.pending.is_some() {
            ready!(self.poll_pending(cx))?;
        }
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

/// hyper's own answers are a status line and a few headers, never this long.
const MAX_REFUSAL: usize = 512;

/// If `head` is one of hyper's own refusals — a whole HTTP/1.1 response head with status 400,
/// 414 or 431, `content-length: 0` and no `content-type` (every answer of the service's has one:
/// `http::error::problem_fallback` gives each error a problem document) — the same answer with a
/// problem document: its status line and headers (the date) kept, the body and its type and
/// length added, and `connection: close` (hyper closes the connection after it).
pub fn problem_for(head: &[u8]) -> Option<Vec<u8>> {
    if head.len() > MAX_REFUSAL || !head.ends_with(b"\r\n\r\n") {
        return None;
    }
    let text = std::str::from_utf8(head).ok()?;
    let mut lines = text.trim_end_matches("\r\n").split("\r\n");
    let status_line = lines.next()?;
    let (slug, title, detail) = match status_line.strip_prefix("HTTP/1.1 ")?.get(..3)? {
        "400" => (
            "malformed",
            "Bad Request",
            "the request is not valid HTTP/1.1: its request line or a header could not be parsed",
        ),
        "414" => {
            ("uri-too-long", "URI Too Long", "the request's path and query are longer than the server accepts (64 KiB)")
        }
        "431" => (
            "request-header-fields-too-large",
            "Request Header Fields Too Large",
            "the request's headers are larger, or more, than the server accepts",
        ),
        _ => return None,
    };
    let headers: Vec<&str> = lines.collect();
    let named = |h: &str, name: &str| h.len() > name.len() && h[..name.len()].eq_ignore_ascii_case(name);
    if headers.iter().any(|h| named(h, "content-type:"))
        || !headers.iter().any(|h| named(h, "content-length:") && h[15..].trim() == "0")
    {
        return None;
    }
    let status: u16 = status_line[9..12].parse().ok()?;
    let body = serde_json::to_vec(&Problem {
        type_: format!("urn:robocal:problem:{slug}"),
        title: title.to_string(),
        status,
        detail: Some(detail.to_string()),
        field: None,
        hint: None,
    })
    .ok()?;
    let mut out = format!("{status_line}\r\n");
    for h in headers.iter().filter(|h| !named(h, "content-length:") && !named(h, "connection:")) {
        out.push_str(h);
        out.push_str("\r\n");
    }
    out.push_str(&format!(
        "content-type: {PROBLEM_JSON}\r\ncontent-length: {}\r\nconnection: close\r\n\r\n",
        body.len()
    ));
    let mut out = out.into_bytes();
    out.extend_from_slice(&body);
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn split(answer: &[u8]) -> (String, serde_json::Value) {
        let at = answer.windows(4).position(|w| w == b"\r\n\r\n").unwrap() + 4;
        (String::from_utf8(answer[..at].to_vec()).unwrap(), serde_json::from_slice(&answer[at..]).unwrap())
    }

    #[test]
    fn hyper_refusals_become_problem_documents() {
        let hyper = b"HTTP/1.1 414 URI Too Long\r\ncontent-length: 0\r\ndate: Thu, 26 Nov 2026 10:00:00 GMT\r\n\r\n";
        let (head, p) = split(&problem_for(hyper).expect("rewritten"));
        assert!(head.starts_with("HTTP/1.1 414 URI Too Long\r\n"), "{head}");
        assert!(head.contains("date: Thu, 26 Nov 2026 10:00:00 GMT\r\n"));
        assert!(head.contains("content-type: application/problem+json\r\n"));
        assert!(head.contains("connection: close\r\n"));
        assert!(!head.contains("content-length: 0"));
        let body_len = serde_json::to_vec(&p).unwrap().len();
        assert!(head.contains(&format!("content-length: {body_len}\r\n")), "{head}");
        assert_eq!(p["status"], 414);
        assert_eq!(p["type"], "urn:robocal:problem:uri-too-long");
        for (code, slug) in [
            ("400 Bad Request", "malformed"),
            ("431 Request Header Fields Too Large", "request-header-fields-too-large"),
        ] {
            let h = format!("HTTP/1.1 {code}\r\nconnection: close\r\ncontent-length: 0\r\n\r\n");
            let (head, p) = split(&problem_for(h.as_bytes()).unwrap());
            assert_eq!(p["type"], format!("urn:robocal:problem:{slug}"));
            assert_eq!(head.matches("connection: close").count(), 1, "{head}");
        }
    }

    #[test]
    fn the_services_own_answers_pass_untouched() {
        for head in [
            // A problem document of the service's: it has a type.
            &b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/problem+json\r\ncontent-length: 0\r\n\r\n"[..],
            // Not a refusal hyper makes.
            b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\n\r\n",
            b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\n\r\n",
            // With a body, or only part of a head.
            b"HTTP/1.1 400 Bad Request\r\ncontent-length: 2\r\n\r\n{}",
            b"HTTP/1.1 414 URI Too Long\r\ncontent-length: 0\r\n",
        ] {
            assert_eq!(problem_for(head), None, "{}", String::from_utf8_lossy(head));
        }
    }

    /// Written through the stream, a refusal goes out rewritten, and hyper is told its own bytes
    /// were written; anything else passes as it is.
    #[tokio::test]
    async fn the_stream_rewrites_refusals_only() {
        use tokio::io::AsyncWriteExt;
        let (a, mut b) = tokio::io::duplex(64);
        let mut s = Refusals::new(a);
        let hyper = b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\n\r\n";
        let reader = tokio::spawn(async move {
            let mut all = Vec::new();
            tokio::io::AsyncReadExt::read_to_end(&mut b, &mut all).await.unwrap();
            all
        });
        let n = std::future::poll_fn(|cx| Pin::new(&mut s).poll_write(cx, hyper)).await.unwrap();
        assert_eq!(n, hyper.len());
        s.write_all(b"plain").await.unwrap();
        s.shutdown().await.unwrap();
        drop(s);
        let all = reader.await.unwrap();
        let mut expected = problem_for(hyper).unwrap();
        expected.extend_from_slice(b"plain");
        assert_eq!(all, expected);
    }
}
