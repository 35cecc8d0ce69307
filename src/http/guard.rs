//! Guards around the handlers:
//! - a body whose declared `Content-Length` is over the limit is refused at once with 413, before
//!   a byte of it is read (and the connection closed: the rest is not read either);
//! - a body that arrives too slowly is cut with 408: after `body_grace` from its first read it
//!   must have come at `body_min_rate` bytes a second on average (the time allowed grows by a
//!   second for each `body_min_rate` bytes received), so a client trickling a body holds a
//!   connection for seconds, not for the whole request timeout. (Headers have their own timeout,
//!   in the server's connection setup: `crate::server`.)
//! - what the storage did is recorded for `/readyz`: an answer given because the storage refused
//!   a write (507/503), and a write that went through after it.

use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use hyper::body::Frame;
use tokio::time::{Instant, Sleep};

use super::error::StorageRefused;
use super::{ApiError, AppState};

/// Middleware: the declared length checked, the body's rate guarded.
pub async fn body(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let config = &state.config;
    let limit = config.max_body_bytes as u64;
    if let Some(declared) = declared_length(req.headers())
        && declared > limit
    {
        return closing(ApiError::TooLarge {
            detail: format!(
                "the request body is declared {declared} bytes long (Content-Length); the server accepts at most {limit}"
            ),
            field: None,
        });
    }
    if req.body().is_end_stream() {
        return next.run(req).await;
    }
    let tripped = Arc::new(AtomicBool::new(false));
    let (min_rate, grace) = (config.body_min_rate.max(1), config.body_grace);
    let req = req.map(|b| Body::new(RateGuard::new(b, min_rate, grace, tripped.clone())));
    let res = next.run(req).await;
    if tripped.load(Ordering::Acquire) {
        return closing(ApiError::BodyTooSlow(format!(
            "the request body arrived too slowly: the server expects it at {min_rate} bytes a second or faster once {} s have passed; nothing of this request was stored",
            grace.as_secs_f64()
        )));
    }
    res
}

/// The declared body length, when there is a valid one.
fn declared_length(headers: &HeaderMap) -> Option<u64> {
    headers.get(header::CONTENT_LENGTH)?.to_str().ok()?.trim().parse().ok()
}

/// An error answered on a connection that is closed after it (its body was not read to the end).
fn closing(e: ApiError) -> Response {
    let mut res = e.into_response();
    res.headers_mut().insert(header::CONNECTION, HeaderValue::from_static("close"));
    res
}

/// A request body that fails once it falls behind its minimum rate.
struct RateGuard {
    inner: Body,
    min_rate: u64,
    grace: Duration,
    /// From the first read (the server's own delays before it reads are not the client's).
    started: Option<Instant>,
    received: u64,
    timer: Pin<Box<Sleep>>,
    tripped: Arc<AtomicBool>,
}

impl RateGuard {
    fn new(inner: Body, min_rate: u64, grace: Duration, tripped: Arc<AtomicBool>) -> Self {
        RateGuard {
            inner,
            min_rate,
            grace,
            started: None,
            received: 0,
            timer: Box::pin(tokio::time::sleep(grace)),
            tripped,
        }
    }

    /// When the body must have arrived by, at what has come so far.
    fn deadline(&self, started: Instant) -> Instant {
        started + self.grace + Duration::from_secs_f64(self.received as f64 / self.min_rate as f64)
    }
}

impl HttpBody for RateGuard {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        let this = self.get_mut();
        let started = *this.started.get_or_insert_with(|| {
            let now = Instant::now();
            this.timer.as_mut().reset(now + this.grace);
            now
        });
        match Pin::new(&mut this.inner).poll_frame(cx) {
            Poll::Ready(Some(Ok(frame))) => {
                if let Some(data) = frame.data_ref() {
                    this.received += data.len() as u64;
                    let d = this.deadline(started);
                    this.timer.as_mut().reset(d);
                }
                Poll::Ready(Some(Ok(frame)))
            }
            Poll::Pending => match this.timer.as_mut().poll(cx) {
                Poll::Ready(()) => {
                    this.tripped.store(true, Ordering::Release);
                    Poll::Ready(Some(Err(axum::Error::new("the request body arrived too slowly"))))
                }
                Poll::Pending => Poll::Pending,
            },
            other => other,
        }
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> hyper::body::SizeHint {
        self.inner.size_hint()
    }
}

/// Middleware: what the storage did, for `/readyz`. An answer marked [`StorageRefused`] records
/// the trouble; a write that went through — an answer 201 or 202 (something was stored; a replay
/// of a stored answer is not a write), or a PUT, PATCH or DELETE answered 2xx — clears it.
pub async fn storage(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let method = req.method().clone();
    let res = next.run(req).await;
    if let Some(StorageRefused(t)) = res.extensions().get::<StorageRefused>() {
        state.storage.failed(*t);
    } else if wrote(&method, res.status(), res.headers()) {
        state.storage.succeeded();
    }
    res
}

fn wrote(method: &Method, status: StatusCode, headers: &HeaderMap) -> bool {
    if headers.contains_key("idempotency-replayed") {
        return false;
    }
    matches!(status, StatusCode::CREATED | StatusCode::ACCEPTED)
        || (status.is_success() && matches!(*method, Method::PUT | Method::PATCH | Method::DELETE))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_are_told_from_reads_and_replays() {
        let none = HeaderMap::new();
        assert!(wrote(&Method::POST, StatusCode::CREATED, &none));
        assert!(wrote(&Method::POST, StatusCode::ACCEPTED, &none));
        assert!(wrote(&Method::DELETE, StatusCode::NO_CONTENT, &none));
        assert!(wrote(&Method::PATCH, StatusCode::OK, &none));
        // Compensation and the RAPID export are POSTs that store nothing.
        assert!(!wrote(&Method::POST, StatusCode::OK, &none));
        assert!(!wrote(&Method::GET, StatusCode::OK, &none));
        assert!(!wrote(&Method::PUT, StatusCode::CONFLICT, &none));
        let mut replayed = HeaderMap::new();
        replayed.insert("idempotency-replayed", HeaderValue::from_static("true"));
        assert!(!wrote(&Method::POST, StatusCode::CREATED, &replayed));
    }

    #[test]
    fn the_declared_length_is_read_when_valid() {
        let mut h = HeaderMap::new();
        assert_eq!(declared_length(&h), None);
        h.insert(header::CONTENT_LENGTH, HeaderValue::from_static("1073741824"));
        assert_eq!(declared_length(&h), Some(1 << 30));
        h.insert(header::CONTENT_LENGTH, HeaderValue::from_static("x"));
        assert_eq!(declared_length(&h), None);
    }

    /// A body from a channel of data chunks.
    struct ChannelBody(tokio::sync::mpsc::Receiver<Bytes>);

    impl HttpBody for ChannelBody {
        type Data = Bytes;
        type Error = std::io::Error;
        fn poll_frame(
            mut self: Pin<&mut Self>,
            cx: &mut Context<'_>,
        ) -> Poll<Option<Result<Frame<Bytes>, Self::Error>>> {
            self.0.poll_recv(cx).map(|b| b.map(|b| Ok(Frame::data(b))))
        }
    }

    /// `n` one-byte chunks, one every `every`, through a guard of 50 bytes a second after 300 ms:
    /// what was read, when it ended, whether it was cut.
    async fn trickle(every: Duration, n: usize) -> (Result<usize, String>, Duration, bool) {
        let (tx, rx) = tokio::sync::mpsc::channel(1);
        let feed = tokio::spawn(async move {
            for _ in 0..n {
                tokio::time::sleep(every).await;
                if tx.send(Bytes::from_static(b"x")).await.is_err() {
                    return;
                }
            }
        });
        let tripped = Arc::new(AtomicBool::new(false));
        let guard = RateGuard::new(Body::new(ChannelBody(rx)), 50, Duration::from_millis(300), tripped.clone());
        let t = Instant::now();
        let got = http_body_util::BodyExt::collect(guard).await.map(|c| c.to_bytes().len()).map_err(|e| e.to_string());
        feed.abort();
        (got, t.elapsed(), tripped.load(Ordering::Acquire))
    }

    /// After n bytes the body must be complete by 0.3 s + n/50 s. A byte every 100 ms: the 3rd
    /// arrives at 0.3 s and extends the deadline to 0.36 s, before the 4th (0.4 s): cut at 0.36 s.
    /// A byte every 5 ms (200 bytes a second) for 1 s passes. (Real time: a loaded machine
    /// delays the bytes and the cut alike, so the bounds are loose.)
    #[tokio::test]
    async fn a_trickled_body_is_cut_and_a_steady_one_passes() {
        let (got, took, tripped) = trickle(Duration::from_millis(100), 20).await;
        assert!(tripped && got.is_err(), "{got:?}");
        assert!(took >= Duration::from_millis(355) && took <= Duration::from_millis(700), "cut after {took:?}");
        let (got, _, tripped) = trickle(Duration::from_millis(5), 200).await;
        assert_eq!(got, Ok(200));
        assert!(!tripped);
    }
}
