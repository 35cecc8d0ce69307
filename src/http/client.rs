//! A small HTTP/1.1 client over hyper for `robocal demo` and the socket tests: one connection per
//! request, plain `http://` only (the demo talks to a server on the cell's network or in-process;
//! put TLS in a reverse proxy). Written on hyper's connection API, already in the dependency tree
//! through axum, rather than adding a full client stack.

use axum::http::{HeaderMap, Method, Request, StatusCode, header};
use http_body_util::{BodyExt, Full};
use hyper::body::Bytes;
use hyper_util::rt::TokioIo;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("bad URL '{0}': use http://host:port")]
    Url(String),
    #[error("cannot connect to {addr}: {source}")]
    Connect { addr: String, source: std::io::Error },
    #[error("HTTP: {0}")]
    Http(String),
    #[error("{method} {path}: {status} {body}")]
    Status { method: String, path: String, status: StatusCode, body: String },
    #[error("{path}: the answer is not the expected JSON: {source}")]
    Decode { path: String, source: serde_json::Error },
}

/// A response.
#[derive(Debug)]
pub struct Answer {
    pub status: StatusCode,
    pub headers: HeaderMap,
    pub body: Bytes,
}

impl Answer {
    pub fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or(Value::Null)
    }
}

#[derive(Clone, Debug)]
pub struct Client {
    /// host:port
    addr: String,
    token: Option<String>,
}

impl Client {
    /// `http://host:port` (a trailing slash is fine).
    pub fn new(url: &str, token: Option<String>) -> Result<Client, ClientError> {
        let rest = url.strip_prefix("http://").ok_or_else(|| ClientError::Url(url.to_string()))?;
        let addr = rest.trim_end_matches('/');
        if addr.is_empty() || addr.contains('/') {
            return Err(ClientError::Url(url.to_string()));
        }
        Ok(Client { addr: addr.to_string(), token })
    }

    pub fn base_url(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// Send a request; any status is returned.
    pub async fn send(
        &self,
        method: Method,
        path: &str,
        body: Option<(&str, Vec<u8>)>,
        headers: &[(&str, &str)],
    ) -> Result<Answer, ClientError> {
        let stream = tokio::net::TcpStream::connect(&self.addr)
            .await
            .map_err(|source| ClientError::Connect { addr: self.addr.clone(), source })?;
        let (mut sender, conn) = hyper::client::conn::http1::handshake(TokioIo::new(stream))
            .await
            .map_err(|e| ClientError::Http(e.to_string()))?;
        tokio::spawn(async move {
            let _ = conn.await;
        });
        let mut req = Request::builder().method(method).uri(path).header(header::HOST, self.addr.as_str());
        if let Some(t) = &self.token {
            req = req.header(header::AUTHORIZATION, format!("Bearer {t}"));
        }
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        let (ct, bytes) = body.map_or((None, Vec::new()), |(ct, b)| (Some(ct), b));
        if let Some(ct) = ct {
            req = req.header(header::CONTENT_TYPE, ct);
        }
        let req = req.body(Full::new(Bytes::from(bytes))).map_err(|e| ClientError::Http(e.to_string()))?;
        let res = sender.send_request(req).await.map_err(|e| ClientError::Http(e.to_string()))?;
        let status = res.status();
        let headers = res.headers().clone();
        let body = res.into_body().collect().await.map_err(|e| ClientError::Http(e.to_string()))?.to_bytes();
        Ok(Answer { status, headers, body })
    }

    /// A JSON request that must succeed (2xx); the answer decoded.
    pub async fn call<T: DeserializeOwned>(
        &self,
        method: Method,
        path: &str,
        body: Option<&impl Serialize>,
    ) -> Result<T, ClientError> {
        let payload = body.map(|b| ("application/json", serde_json::to_vec(b).expect("requests serialise")));
        let m = method.to_string();
        let a = self.send(method, path, payload, &[]).await?;
        if !a.status.is_success() {
            return Err(ClientError::Status {
                method: m,
                path: path.to_string(),
                status: a.status,
                body: String::from_utf8_lossy(&a.body).into_owned(),
            });
        }
        serde_json::from_slice(&a.body).map_err(|source| ClientError::Decode { path: path.to_string(), source })
    }

    pub async fn get<T: DeserializeOwned>(&self, path: &str) -> Result<T, ClientError> {
        self.call(Method::GET, path, None::<&Value>).await
    }

    pub async fn post<T: DeserializeOwned>(&self, path: &str, body: &impl Serialize) -> Result<T, ClientError> {
        self.call(Method::POST, path, Some(body)).await
    }
}
