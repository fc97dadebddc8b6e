//! The HTTP edge: connections accepted under a cap, hyper with a header-read timeout, requests whose
//! target or headers are too long answered with the JSON error body, and a shutdown that waits for
//! open connections only up to a deadline.
//!
//! axum's own `serve` sets no timer (so hyper's header-read timeout is off: a client that never
//! finishes its headers holds its connection for ever) and accepts without bound (~20 000 half-open
//! connections exhausted the file descriptors); this loop is the same as axum's with both bounded.

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::Request;
use axum::http::StatusCode;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::net::TcpListener;

use crate::api::ApiError;

/// The edge's bounds (from [`crate::settings::Settings`]).
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Connections open at once; the next one waits in the kernel's backlog until one closes.
    pub max_connections: usize,
    /// How long a client may take to send a request's headers (each request of a keep-alive
    /// connection, and the wait for the next one): past it, the connection is closed.
    pub header_read_timeout: Duration,
    /// How long a shutdown waits for open connections (live streams, slow clients) to finish.
    pub shutdown_deadline: Duration,
}

/// Longest request target (path and query), bytes: past it, 414 with the JSON error body.
pub const MAX_URI_BYTES: usize = 8 << 10;
/// Most bytes of request headers (names and values): past it, 431 with the JSON error body.
pub const MAX_HEADER_BYTES: usize = 32 << 10;

/// Serves `app` on `listener` until `shutdown` resolves, then lets open connections finish for at
/// most `limits.shutdown_deadline`.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: Limits,
    shutdown: impl Future<Output = ()>,
) -> std::io::Result<()> {
    let permits = Arc::new(tokio::sync::Semaphore::new(limits.max_connections.max(1)));
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    // HTTP/1.1 only, as axum's own serve speaks with its default features.
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_read_timeout);
    let app = app.layer(axum::middleware::from_fn(bound_request_head));
    tokio::pin!(shutdown);
    loop {
        let permit = tokio::select! {
            p = permits.clone().acquire_owned() => p.expect("the semaphore is never closed"),
            _ = &mut shutdown => break,
        };
        let stream = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    // Out of file descriptors and the like: wait rather than spin (as axum does).
                    tracing::warn!("accept error: {e}");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
            _ = &mut shutdown => break,
        };
        let _ = stream.set_nodelay(true);
        let service = TowerToHyperService::new(app.clone());
        let conn = graceful.watch(builder.serve_connection(TokioIo::new(stream), service));
        tokio::spawn(async move {
            if let Err(e) = conn.await {
                tracing::trace!("connection ended: {e}");
            }
            drop(permit);
        });
    }
    drop(listener);
    if tokio::time::timeout(limits.shutdown_deadline, graceful.shutdown())
        .await
        .is_err()
    {
        tracing::warn!(
            deadline_s = limits.shutdown_deadline.as_secs_f64(),
            "connections still open at the shutdown deadline: closed"
        );
    }
    Ok(())
}

/// Refuses a request whose target or headers are longer than the edge allows, with the JSON body
/// (hyper itself answers only far larger ones, with an empty body).
async fn bound_request_head(req: Request, next: Next) -> Response {
    let uri = req.uri().to_string().len();
    if uri > MAX_URI_BYTES {
        return ApiError::new(
            StatusCode::URI_TOO_LONG,
            "uri_too_long",
            format!("the request target has {uri} bytes; at most {MAX_URI_BYTES}"),
        )
        .into_response();
    }
    let head: usize = req
        .headers()
        .iter()
        .map(|(k, v)| k.as_str().len() + v.len())
        .sum();
    if head > MAX_HEADER_BYTES {
        return ApiError::new(
            StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            "headers_too_large",
            format!("the request headers have {head} bytes; at most {MAX_HEADER_BYTES}"),
        )
        .into_response();
    }
    next.run(req).await
}
