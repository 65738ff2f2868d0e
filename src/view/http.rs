//! The HTTP plumbing `rigidsim view --serve` and `rigidsim live` share:
//! axum on a tokio runtime of one thread, bound at once (a port in use is
//! an error there, port 0 is known), stopped on request; and the replay
//! page's own server.

use axum::Router;
use axum::http::{Method, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};
use tokio::sync::oneshot;

/// A running server: its address, and how to stop it.
pub struct Server {
    pub addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Server {
    /// Stops accepting, lets open connections send what they hold (up to a
    /// second), and ends the server's thread.
    pub fn stop(mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Binds `addr` now (so a port in use is an error here, and port 0 is
/// known) and serves `router` on a thread of its own until stopped.
pub(crate) fn spawn(
    addr: SocketAddr,
    router: Router,
    open: Option<Arc<AtomicUsize>>,
) -> std::io::Result<Server> {
    let listener = std::net::TcpListener::bind(addr)?;
    listener.set_nonblocking(true)?;
    let addr = listener.local_addr()?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let (stop, stopped) = oneshot::channel::<()>();
    let thread = std::thread::Builder::new()
        .name("live-server".into())
        .spawn(move || {
            runtime.block_on(async move {
                let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                    return;
                };
                let _ = axum::serve(listener, router)
                    .with_graceful_shutdown(async {
                        let _ = stopped.await;
                    })
                    .await;
                // Upgraded connections are not the server's to wait for:
                // give them a moment to send the live run's last messages.
                if let Some(open) = open {
                    let until = Instant::now() + Duration::from_secs(1);
                    while open.load(Ordering::SeqCst) > 0 && Instant::now() < until {
                        tokio::time::sleep(Duration::from_millis(10)).await;
                    }
                }
            });
        })?;
    Ok(Server {
        addr,
        stop: Some(stop),
        thread: Some(thread),
    })
}

/// `rigidsim view --serve`: `page` at `/` and `/replay.html` on
/// 127.0.0.1:`port` until the process ends; prints the address first.
pub(super) fn serve_page(page: Vec<u8>, port: u16) -> std::io::Result<()> {
    let page = Arc::new(page);
    let only_get = || async { plain(StatusCode::METHOD_NOT_ALLOWED, "only GET\n") };
    let the_page = || {
        let page = Arc::clone(&page);
        get(move || async move { replay_page(&page) }).fallback(only_get)
    };
    let router = Router::new()
        .route("/", the_page())
        .route("/replay.html", the_page())
        .fallback(|method: Method| async move {
            if method == Method::GET || method == Method::HEAD {
                plain(StatusCode::NOT_FOUND, "not found: the replay is at /\n")
            } else {
                plain(StatusCode::METHOD_NOT_ALLOWED, "only GET\n")
            }
        });
    let server = spawn((std::net::Ipv4Addr::LOCALHOST, port).into(), router, None)?;
    let port = server.addr.port();
    println!(
        "serving at http://127.0.0.1:{port}/ (Ctrl-C stops; from another machine: ssh -L {port}:127.0.0.1:{port} THIS_HOST, then open that address there)"
    );
    use std::io::Write;
    let _ = std::io::stdout().flush();
    if let Some(t) = server.thread {
        let _ = t.join();
    }
    Ok(())
}

/// A page or a short text, never cached, on a connection that then closes
/// (one file is all a replay asks for).
fn replay_page(page: &[u8]) -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
            (header::CONNECTION, "close"),
        ],
        page.to_vec(),
    )
        .into_response()
}

/// A short text reply, never cached, on a connection that then closes.
pub(crate) fn plain(status: StatusCode, text: &'static str) -> Response {
    (
        status,
        [
            (header::CONTENT_TYPE, "text/plain; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
            (header::CONNECTION, "close"),
        ],
        text,
    )
        .into_response()
}
