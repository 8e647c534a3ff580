//! Problem bodies for the errors hyper answers by itself.
//!
//! A request whose head hyper cannot parse never reaches a handler or a
//! middleware: hyper writes a bare status line (`400`, `414` for a target
//! over 65,534 bytes, `431` for a head over its buffer) with an empty body
//! and closes the connection. Every other error of this API is
//! `application/problem+json`, and a client should not need a second way to
//! read errors. This module wraps each accepted connection so that exactly
//! those automatic answers, recognised by their shape (one of those
//! statuses, no `content-type`, `content-length: 0`, at the start of a
//! write), go out with a problem body instead. Responses of the router
//! always carry a content type and pass untouched. (Targets over 8 KiB but
//! within hyper's limit are refused by the router itself, see
//! [`crate::routes`].)

use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};

/// A TCP listener whose connections rewrite hyper's automatic errors.
pub struct ProblemListener(pub TcpListener);

impl axum::serve::Listener for ProblemListener {
    type Io = ProblemStream<TcpStream>;
    type Addr = std::net::SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        let (io, addr) = axum::serve::Listener::accept(&mut self.0).await;
        (ProblemStream::new(io), addr)
    }

    fn local_addr(&self) -> io::Result<Self::Addr> {
        self.0.local_addr()
    }
}

/// A connection whose writes are watched for hyper's bare error heads.
pub struct ProblemStream<S> {
    inner: S,
    /// A rewritten answer still to be written, and how much of it was.
    pending: Vec<u8>,
    written: usize,
}

impl<S> ProblemStream<S> {
    pub fn new(inner: S) -> Self {
        Self {
            inner,
            pending: Vec::new(),
            written: 0,
        }
    }
}

/// The detail of each status hyper answers by itself.
fn detail(status: u16) -> Option<&'static str> {
    match status {
        400 => Some("the request line or a header could not be parsed as HTTP/1.1"),
        414 => Some("the request target exceeds 65,534 bytes; this API's URLs are far shorter"),
        431 => Some("the request head exceeds the server's buffer; send fewer or shorter headers"),
        _ => None,
    }
}

/// The answer with a problem body, when `buf` starts with one of hyper's
/// automatic error heads (a whole head, without a content type and with an
/// empty body); `None` for anything else.
pub fn rewrite(buf: &[u8]) -> Option<Vec<u8>> {
    let end = buf.windows(4).position(|w| w == b"\r\n\r\n")?;
    let head = std::str::from_utf8(&buf[..end]).ok()?;
    let mut lines = head.split("\r\n");
    let status_line = lines.next()?;
    let status: u16 = status_line
        .strip_prefix("HTTP/1.1 ")?
        .get(..3)?
        .parse()
        .ok()?;
    let detail = detail(status)?;
    let headers: Vec<&str> = lines.collect();
    let named = |name: &str| {
        headers
            .iter()
            .any(|h| h.len() > name.len() && h[..name.len()].eq_ignore_ascii_case(name))
    };
    let empty = headers
        .iter()
        .any(|h| h.eq_ignore_ascii_case("content-length: 0"));
    if named("content-type:") || !empty {
        return None;
    }
    let title = status_line.get(13..).unwrap_or("Error");
    let body = serde_json::json!({
        "type": "about:blank",
        "title": title,
        "status": status,
        "detail": detail,
    })
    .to_string();
    let mut out = format!("{status_line}\r\n");
    for h in headers
        .iter()
        .filter(|h| !h.to_ascii_lowercase().starts_with("content-length:"))
    {
        out.push_str(h);
        out.push_str("\r\n");
    }
    out.push_str("content-type: application/problem+json\r\n");
    out.push_str(&format!("content-length: {}\r\n\r\n{body}", body.len()));
    let mut bytes = out.into_bytes();
    // Whatever followed the head in this write (nothing, for an empty body).
    bytes.extend_from_slice(&buf[end + 4..]);
    Some(bytes)
}

impl<S: AsyncWrite + Unpin> ProblemStream<S> {
    /// Writes what is pending; ready when nothing is.
    fn drain(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        while self.written < self.pending.len() {
            let n = match Pin::new(&mut self.inner).poll_write(cx, &self.pending[self.written..]) {
                Poll::Ready(Ok(n)) => n,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => return Poll::Pending,
            };
            if n == 0 {
                return Poll::Ready(Err(io::ErrorKind::WriteZero.into()));
            }
            self.written += n;
        }
        self.pending.clear();
        self.written = 0;
        Poll::Ready(Ok(()))
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for ProblemStream<S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for ProblemStream<S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        if let Poll::Ready(Err(e)) = this.drain(cx) {
            return Poll::Ready(Err(e));
        }
        if !this.pending.is_empty() {
            return Poll::Pending;
        }
        if buf.starts_with(b"HTTP/1.1 4") {
            if let Some(answer) = rewrite(buf) {
                this.pending = answer;
                // The caller's bytes are taken: they go out rewritten.
                return match this.drain(cx) {
                    Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
                    _ => Poll::Ready(Ok(buf.len())),
                };
            }
        }
        Pin::new(&mut this.inner).poll_write(cx, buf)
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        match this.drain(cx) {
            Poll::Ready(Ok(())) => Pin::new(&mut this.inner).poll_flush(cx),
            other => other,
        }
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        match this.drain(cx) {
            Poll::Ready(Ok(())) => Pin::new(&mut this.inner).poll_shutdown(cx),
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_hypers_bare_error_heads_are_rewritten() {
        let bare = b"HTTP/1.1 414 URI Too Long\r\nconnection: close\r\ncontent-length: 0\r\ndate: Tue, 24 Nov 2026 12:00:00 GMT\r\n\r\n";
        let answer = String::from_utf8(rewrite(bare).unwrap()).unwrap();
        let (head, body) = answer.split_once("\r\n\r\n").unwrap();
        assert!(head.starts_with("HTTP/1.1 414 URI Too Long\r\n"));
        assert!(head.contains("content-type: application/problem+json"));
        assert!(head.contains("connection: close") && head.contains("date: "));
        assert!(head.contains(&format!("content-length: {}", body.len())));
        let problem: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(problem["status"], 414);
        assert_eq!(problem["title"], "URI Too Long");
        assert!(problem["detail"].as_str().unwrap().contains("65,534"));
        // The router's own problems carry a content type: untouched.
        let ours = b"HTTP/1.1 414 URI Too Long\r\ncontent-type: application/problem+json\r\ncontent-length: 80\r\n\r\n{}";
        assert!(rewrite(ours).is_none());
        // Other statuses, bodies, half heads: untouched.
        assert!(rewrite(b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\n\r\n").is_none());
        assert!(rewrite(b"HTTP/1.1 400 Bad Request\r\ncontent-length: 5\r\n\r\nhello").is_none());
        assert!(rewrite(b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-le").is_none());
        assert!(rewrite(
            b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\n\r\n"
        )
        .is_some());
    }

    #[tokio::test]
    async fn a_rewritten_answer_reaches_the_peer_whole_through_partial_writes() {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        // A pipe of 7 bytes forces partial writes.
        let (near, mut far) = tokio::io::duplex(7);
        let mut stream = ProblemStream::new(near);
        let bare = b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\r\n";
        let reader = tokio::spawn(async move {
            let mut all = Vec::new();
            far.read_to_end(&mut all).await.unwrap();
            all
        });
        stream.write_all(bare).await.unwrap();
        stream
            .write_all(b"HTTP/1.1 200 OK\r\ncontent-length: 2\r\n\r\nok")
            .await
            .unwrap();
        stream.shutdown().await.unwrap();
        drop(stream);
        let all = String::from_utf8(reader.await.unwrap()).unwrap();
        assert!(all.starts_with("HTTP/1.1 400 Bad Request\r\n"), "{all}");
        assert!(all.contains("application/problem+json"));
        assert!(
            all.ends_with("HTTP/1.1 200 OK\r\ncontent-length: 2\r\n\r\nok"),
            "{all}"
        );
    }
}
