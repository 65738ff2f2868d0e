//! The HTTP and WebSocket server of `rigidsim live`: axum on a tokio
//! runtime of one thread beside the simulation (`crate::view::http`).
//! The live run's page at `/`, its WebSocket at `/ws` (messages in
//! `protocol`).
//!
//! Safety on a lab's network: the server listens on loopback unless told
//! otherwise; bound beyond it, every request must carry the live run's
//! random `token` (the printed URL has it), since anyone who reaches the
//! port could otherwise stop a live run. A WebSocket upgrade whose `Origin`
//! is not the page's own is refused (another site open in the same browser
//! cannot drive the live run). Each connection is one hand: it has its own
//! grab, released when it goes away.

use super::protocol::{self, Input, SceneFacts};
pub use crate::view::http::Server;
use crate::view::http::{plain, spawn};
use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU32, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Instant;
use tokio::sync::watch;

/// A message larger than this closes its connection (tungstenite's own
/// limit); between `protocol::MAX_MESSAGE_BYTES` and this it is answered
/// with an error and the connection stays.
const HARD_MESSAGE_LIMIT: usize = 64 * 1024;

/// What the connections share with the live run.
pub struct Shared {
    /// The page at `/`.
    pub page: String,
    /// The `scene` message every connection gets first.
    pub scene: Arc<str>,
    /// What inputs are checked against; the live run keeps the bodies'
    /// centres current.
    pub facts: Mutex<SceneFacts>,
    /// The latest `state` (or the final `end`) message.
    pub states: watch::Receiver<Arc<str>>,
    /// Inputs to the live run, with the hand (connection) that sent them.
    pub inputs: Mutex<mpsc::Sender<(u32, Input)>>,
    /// Required as `?token=` on every request, when bound beyond loopback.
    pub token: Option<String>,
    next_hand: AtomicU32,
    /// Connections open now (the server waits for them when it stops).
    open: Arc<AtomicUsize>,
}

impl Shared {
    pub fn new(
        page: String,
        scene: Arc<str>,
        facts: SceneFacts,
        states: watch::Receiver<Arc<str>>,
        inputs: mpsc::Sender<(u32, Input)>,
        token: Option<String>,
    ) -> Shared {
        Shared {
            page,
            scene,
            facts: Mutex::new(facts),
            states,
            inputs: Mutex::new(inputs),
            token,
            next_hand: AtomicU32::new(1),
            open: Arc::new(AtomicUsize::new(0)),
        }
    }

    fn send(&self, hand: u32, input: Input) -> bool {
        self.inputs.lock().unwrap().send((hand, input)).is_ok()
    }
}

/// A random token of 32 hex digits, from the system's generator.
pub fn random_token() -> std::io::Result<String> {
    use std::io::Read;
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Starts the live run's server on `addr`.
pub fn start_live(addr: SocketAddr, shared: Arc<Shared>) -> std::io::Result<Server> {
    let router = Router::new()
        .route("/", get(live_page))
        .route("/ws", get(upgrade))
        // Browsers ask for an icon; there is none, and saying so is no error.
        .route("/favicon.ico", get(|| async { StatusCode::NO_CONTENT }))
        .fallback(not_found)
        .with_state(Arc::clone(&shared));
    let open = Arc::clone(&shared.open);
    spawn(addr, router, Some(open))
}

async fn not_found() -> Response {
    plain(
        StatusCode::NOT_FOUND,
        "not found: the live run's page is at /, its WebSocket at /ws\n",
    )
}

/// Whether the request carries the live run's token (always, on loopback).
fn admitted(shared: &Shared, query: &HashMap<String, String>) -> bool {
    match &shared.token {
        None => true,
        Some(t) => query.get("token") == Some(t),
    }
}

async fn live_page(
    State(shared): State<Arc<Shared>>,
    Query(query): Query<HashMap<String, String>>,
) -> Response {
    if !admitted(&shared, &query) {
        return plain(
            StatusCode::FORBIDDEN,
            "this live run needs its token: open the URL rigidsim printed\n",
        );
    }
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        shared.page.clone(),
    )
        .into_response()
}

/// Whether an upgrade's `Origin` (if it has one: browsers always send it,
/// scripts need not) is the page this server serves, `http://HOST`.
fn same_origin(headers: &HeaderMap) -> bool {
    let Some(origin) = headers.get(header::ORIGIN) else {
        return true;
    };
    let host = headers.get(header::HOST).and_then(|h| h.to_str().ok());
    match (origin.to_str(), host) {
        (Ok(origin), Some(host)) => origin == format!("http://{host}"),
        _ => false,
    }
}

async fn upgrade(
    ws: WebSocketUpgrade,
    headers: HeaderMap,
    State(shared): State<Arc<Shared>>,
    Query(query): Query<HashMap<String, String>>,
) -> Response {
    if !admitted(&shared, &query) {
        return plain(StatusCode::FORBIDDEN, "this live run needs its token\n");
    }
    if !same_origin(&headers) {
        return plain(
            StatusCode::FORBIDDEN,
            "a WebSocket from another site's page is refused\n",
        );
    }
    ws.max_message_size(HARD_MESSAGE_LIMIT)
        .max_frame_size(HARD_MESSAGE_LIMIT)
        .on_upgrade(move |socket| connection(socket, shared))
}

/// A refill-as-you-go allowance of messages: `MAX_MESSAGES_PER_SECOND`
/// on average, as many at once.
struct Allowance {
    left: f64,
    at: Instant,
}

impl Allowance {
    fn take(&mut self) -> bool {
        let rate = protocol::MAX_MESSAGES_PER_SECOND;
        let now = Instant::now();
        self.left = (self.left + (now - self.at).as_secs_f64() * rate).min(rate);
        self.at = now;
        if self.left >= 1.0 {
            self.left -= 1.0;
            true
        } else {
            false
        }
    }
}

/// One client: the scene, then states as the live run publishes them, and
/// its inputs checked and passed on (or answered with an error).
async fn connection(mut socket: WebSocket, shared: Arc<Shared>) {
    shared.open.fetch_add(1, Ordering::SeqCst);
    let hand = shared.next_hand.fetch_add(1, Ordering::SeqCst);
    let mut states = shared.states.clone();
    states.mark_changed();
    let text = |s: &str| Message::Text(s.into());
    let mut holding = false;
    let mut allowance = Allowance {
        left: protocol::MAX_MESSAGES_PER_SECOND,
        at: Instant::now(),
    };
    if socket.send(text(&shared.scene)).await.is_ok() {
        loop {
            tokio::select! {
                incoming = socket.recv() => {
                    let reply = match incoming {
                        Some(Ok(Message::Text(t))) => {
                            if !allowance.take() {
                                Some(format!(
                                    "too many messages: at most {} a second",
                                    protocol::MAX_MESSAGES_PER_SECOND
                                ))
                            } else {
                                let parsed = Input::parse(t.as_str(), &shared.facts.lock().unwrap());
                                match parsed {
                                    Err(e) => Some(e),
                                    Ok(Input::Drag { .. }) if !holding => {
                                        Some("drag without a grab: send grab first".into())
                                    }
                                    Ok(input) => {
                                        match input {
                                            Input::Grab { .. } => holding = true,
                                            Input::Release | Input::Reset => holding = false,
                                            _ => {}
                                        }
                                        if !shared.send(hand, input) {
                                            break;
                                        }
                                        None
                                    }
                                }
                            }
                        }
                        Some(Ok(Message::Binary(_))) => {
                            Some("binary messages are not part of the protocol: send JSON text".into())
                        }
                        Some(Ok(Message::Ping(_) | Message::Pong(_))) => None,
                        _ => break,
                    };
                    if let Some(reply) = reply {
                        if socket.send(text(&protocol::error_message(&reply))).await.is_err() {
                            break;
                        }
                    }
                }
                changed = states.changed() => {
                    if changed.is_err() {
                        break;
                    }
                    let message = states.borrow_and_update().clone();
                    if !message.is_empty() && socket.send(text(&message)).await.is_err() {
                        break;
                    }
                }
            }
        }
    }
    if holding {
        shared.send(hand, Input::Release);
    }
    let _ = socket.send(Message::Close(None)).await;
    shared.open.fetch_sub(1, Ordering::SeqCst);
}
