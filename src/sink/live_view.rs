//! Live view: a [Foxglove WebSocket](https://github.com/foxglove/ws-protocol) server
//! (subprotocol `foxglove.websocket.v1`) that the Foxglove app connects to.
//!
//! The publishing side ([`LiveView::add_channel`], [`LiveView::publish`]) is called from the
//! thread that decodes; it never waits for a client. Each client has a small bounded queue
//! (messages and bytes, [`ServeOptions`]); a message that does not fit is dropped for that client
//! and counted ([`LiveViewStats`]), so one slow client neither slows the decoder nor the other
//! clients. Payloads are shared between the queues (one copy per message, not per client).
//!
//! The server runs on its own thread with a single-threaded tokio runtime: one task per client
//! that writes its queue to the socket and reads its `subscribe` / `unsubscribe` requests.
//!
//! Protocol, as the server speaks it:
//! - on connect: a `serverInfo` text message (no capabilities), then one `advertise` of every
//!   channel known so far (possibly empty); later channels are advertised as they appear;
//! - client `subscribe` (`subscriptions: [{id, channelId}]`) and `unsubscribe`
//!   (`subscriptionIds: [...]`); invalid requests (unknown channel, reused id, a second
//!   subscription of one channel) are ignored;
//! - `messageData` binary frames: opcode `0x01`, subscription id (u32 LE), log time in ns (u64
//!   LE), then the payload, exactly as advertised (`protobuf` with a base64
//!   `FileDescriptorSet` schema for the ringscan channels).

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use futures_util::{SinkExt as _, StreamExt as _};
use serde_json::{json, Value};
use tokio::sync::mpsc;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::Message;

/// The WebSocket subprotocol spoken.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// Opcode of a `messageData` binary frame.
pub const OP_MESSAGE_DATA: u8 = 0x01;
/// Messages queued per client at most, by default: a few sweeps (a slow client gets the newest
/// sweeps it can take, not a growing backlog).
pub const DEFAULT_QUEUE_MESSAGES: usize = 8;
/// Payload bytes queued per client at most, by default.
pub const DEFAULT_QUEUE_BYTES: usize = 64 << 20;
/// Connections (in the handshake or connected) served at once, by default.
pub const DEFAULT_MAX_CLIENTS: usize = 16;
/// Largest message a client may send (its requests are small JSON objects).
const MAX_CLIENT_MESSAGE: usize = 1 << 20;
/// Time a connection has to complete its WebSocket handshake.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
/// While closing, the wait for clients' queues ends after this long without a message written.
const DRAIN_STALL: Duration = Duration::from_millis(300);
/// Finished clients kept for [`LiveView::clients`].
const CLIENT_HISTORY: usize = 64;

/// Settings of a [`LiveView`].
#[derive(Clone, Debug)]
pub struct ServeOptions {
    /// Server name sent in `serverInfo`.
    pub name: String,
    /// Messages queued per client at most (≥ 1).
    pub queue_messages: usize,
    /// Payload bytes queued per client at most (a single larger message is still queued when
    /// the queue is empty, so no message is too large to be sent).
    pub queue_bytes: usize,
    /// Connections served at once; more are closed at once (so memory stays bounded).
    pub max_clients: usize,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            name: "ringscan".to_string(),
            queue_messages: DEFAULT_QUEUE_MESSAGES,
            queue_bytes: DEFAULT_QUEUE_BYTES,
            max_clients: DEFAULT_MAX_CLIENTS,
        }
    }
}

/// A channel to advertise.
#[derive(Clone, Debug)]
pub struct ChannelSpec<'a> {
    /// Topic, e.g. `/points`.
    pub topic: &'a str,
    /// Message encoding, e.g. `protobuf`.
    pub encoding: &'a str,
    /// Schema name, e.g. `foxglove.PointCloud`.
    pub schema_name: &'a str,
    /// The schema: for `protobuf` a serialized `FileDescriptorSet` (sent base64-encoded).
    pub schema: &'a [u8],
}

/// Handle of a channel made by [`LiveView::add_channel`] (its id in the protocol).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ChannelId(pub u32);

/// Counters of a [`LiveView`], updated as it runs.
#[derive(Debug, Default)]
pub struct LiveViewStats {
    /// Clients connected now.
    pub clients_connected: AtomicU64,
    /// Clients that completed the handshake since the start.
    pub clients_total: AtomicU64,
    /// Connections refused or failed during the handshake (wrong subprotocol, not WebSocket).
    pub handshakes_failed: AtomicU64,
    /// Connections closed at once because `max_clients` were being served.
    pub clients_refused: AtomicU64,
    /// Messages handed to clients' queues.
    pub messages_queued: AtomicU64,
    /// Messages written to clients' sockets.
    pub messages_sent: AtomicU64,
    /// Bytes of `messageData` frames written.
    pub bytes_sent: AtomicU64,
    /// Messages dropped because a client's queue was full (summed over clients).
    pub messages_dropped: AtomicU64,
}

/// Counters of one client.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ClientStats {
    /// The client's address.
    pub peer: Option<SocketAddr>,
    /// Messages written to its socket.
    pub sent: u64,
    /// Messages dropped because its queue was full.
    pub dropped: u64,
    /// Whether it was still connected (when the server closed: its queue did not drain in time).
    pub connected: bool,
}

/// Why the server could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// The address could not be bound.
    #[error("--serve {addr}: {source}")]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// The OS error.
        source: std::io::Error,
    },
    /// The server thread or its runtime could not start.
    #[error("starting the live view server: {0}")]
    Start(std::io::Error),
}

/// One message in a client's queue.
struct Queued {
    subscription: u32,
    log_time_ns: u64,
    payload: Arc<[u8]>,
}

/// The publishing side's view of one client.
struct ClientSlot {
    id: u64,
    /// (channel, subscription id) pairs.
    subscriptions: Vec<(u32, u32)>,
    data: mpsc::Sender<Queued>,
    control: mpsc::UnboundedSender<String>,
    counters: Arc<ClientCounters>,
}

#[derive(Default)]
struct ClientCounters {
    queued_bytes: AtomicUsize,
    sent: AtomicU64,
    dropped: AtomicU64,
}

struct State {
    /// Advertisement of each channel (its JSON object), by id − 1.
    channels: Vec<Value>,
    clients: Vec<ClientSlot>,
    /// Counters of every connected client (kept while closing, when `clients` is emptied).
    connected: Vec<(u64, SocketAddr, Arc<ClientCounters>)>,
    next_client: u64,
    history: VecDeque<ClientStats>,
    /// No more clients are taken once closing.
    closing: bool,
}

struct Shared {
    state: Mutex<State>,
    stats: Arc<LiveViewStats>,
    opts: ServeOptions,
    session_id: String,
}

impl Shared {
    fn state(&self) -> MutexGuard<'_, State> {
        // A panic while holding the lock leaves consistent data (every update is one push or
        // retain): keep serving.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A running live view server. Dropping it stops the server without waiting for queues to
/// drain; [`LiveView::close`] lets them drain first.
pub struct LiveView {
    shared: Arc<Shared>,
    local_addr: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<Duration>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveView")
            .field("local_addr", &self.local_addr)
            .finish_non_exhaustive()
    }
}

impl LiveView {
    /// Binds `addr` (port 0: any free port, see [`LiveView::local_addr`]) and starts serving.
    pub fn bind(addr: SocketAddr, opts: ServeOptions) -> Result<Self, ServeError> {
        let listener = std::net::TcpListener::bind(addr)
            .map_err(|source| ServeError::Bind { addr, source })?;
        listener
            .set_nonblocking(true)
            .map_err(|source| ServeError::Bind { addr, source })?;
        let local_addr = listener
            .local_addr()
            .map_err(|source| ServeError::Bind { addr, source })?;
        let opts = ServeOptions {
            queue_messages: opts.queue_messages.max(1),
            ..opts
        };
        // A session id that differs between runs (the protocol lets clients tell a restarted
        // server from a reconnection): the start time.
        let session_id = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos().to_string())
            .unwrap_or_default();
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                channels: Vec::new(),
                clients: Vec::new(),
                connected: Vec::new(),
                next_client: 0,
                history: VecDeque::new(),
                closing: false,
            }),
            stats: Arc::new(LiveViewStats::default()),
            opts,
            session_id,
        });
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(ServeError::Start)?;
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel();
        let server = shared.clone();
        let thread = std::thread::Builder::new()
            .name("ringscan-serve".into())
            .spawn(move || rt.block_on(serve(listener, server, stop_rx)))
            .map_err(ServeError::Start)?;
        Ok(Self {
            shared,
            local_addr,
            stop: Some(stop_tx),
            thread: Some(thread),
        })
    }

    /// The address served.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// The counters (shared: they keep counting while the server runs).
    pub fn stats(&self) -> Arc<LiveViewStats> {
        self.shared.stats.clone()
    }

    /// Per-client counters: up to 64 clients that left, oldest first, then those connected.
    pub fn clients(&self) -> Vec<ClientStats> {
        let st = self.shared.state();
        let mut v: Vec<ClientStats> = st.history.iter().cloned().collect();
        v.extend(st.connected.iter().map(|(_, peer, c)| ClientStats {
            peer: Some(*peer),
            sent: c.sent.load(Ordering::Relaxed),
            dropped: c.dropped.load(Ordering::Relaxed),
            connected: true,
        }));
        v
    }

    /// Adds a channel and advertises it to every client (and to clients that connect later).
    pub fn add_channel(&self, spec: &ChannelSpec<'_>) -> ChannelId {
        let mut st = self.shared.state();
        let id = st.channels.len() as u32 + 1;
        let adv = json!({
            "id": id,
            "topic": spec.topic,
            "encoding": spec.encoding,
            "schemaName": spec.schema_name,
            "schema": base64(spec.schema),
            "schemaEncoding": spec.encoding,
        });
        let msg = json!({"op": "advertise", "channels": [adv.clone()]}).to_string();
        st.channels.push(adv);
        for c in &st.clients {
            let _ = c.control.send(msg.clone());
        }
        ChannelId(id)
    }

    /// Whether any client subscribes to `channel` (encode a message only then).
    pub fn has_subscribers(&self, channel: ChannelId) -> bool {
        self.shared
            .state()
            .clients
            .iter()
            .any(|c| c.subscriptions.iter().any(|&(ch, _)| ch == channel.0))
    }

    /// Queues `payload` (logged at `log_time_ns`) for every client subscribed to `channel`.
    /// Never waits: a client whose queue is full misses this message, which is counted.
    /// Returns the number of clients it was queued for.
    pub fn publish(&self, channel: ChannelId, log_time_ns: u64, payload: &[u8]) -> usize {
        let st = self.shared.state();
        let mut shared_payload: Option<Arc<[u8]>> = None;
        let mut queued = 0;
        let budget = self.shared.opts.queue_bytes;
        let stats = &self.shared.stats;
        for c in &st.clients {
            let Some(&(_, subscription)) = c.subscriptions.iter().find(|&&(ch, _)| ch == channel.0)
            else {
                continue;
            };
            let held = c.counters.queued_bytes.load(Ordering::Relaxed);
            if held > 0 && held.saturating_add(payload.len()) > budget {
                c.counters.dropped.fetch_add(1, Ordering::Relaxed);
                stats.messages_dropped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            let p = shared_payload
                .get_or_insert_with(|| Arc::from(payload))
                .clone();
            match c.data.try_send(Queued {
                subscription,
                log_time_ns,
                payload: p,
            }) {
                Ok(()) => {
                    c.counters
                        .queued_bytes
                        .fetch_add(payload.len(), Ordering::Relaxed);
                    stats.messages_queued.fetch_add(1, Ordering::Relaxed);
                    queued += 1;
                }
                Err(mpsc::error::TrySendError::Full(_)) => {
                    c.counters.dropped.fetch_add(1, Ordering::Relaxed);
                    stats.messages_dropped.fetch_add(1, Ordering::Relaxed);
                }
                // The client is leaving; its task removes it.
                Err(mpsc::error::TrySendError::Closed(_)) => {}
            }
        }
        queued
    }

    /// Stops taking clients, lets every client's queue drain for at most `drain`, closes the
    /// connections and ends the server thread. Returns every client's final counters (the last
    /// 64 clients).
    pub fn close(mut self, drain: Duration) -> Vec<ClientStats> {
        self.shutdown(drain);
        self.clients()
    }

    fn shutdown(&mut self, drain: Duration) {
        {
            let mut st = self.shared.state();
            st.closing = true;
            // Dropping the senders ends each client's writer once its queue is written.
            st.clients.clear();
        }
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(drain);
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.shutdown(Duration::ZERO);
    }
}

/// The accept loop; on `stop`, waits up to the given time for the clients to finish.
async fn serve(
    listener: std::net::TcpListener,
    shared: Arc<Shared>,
    mut stop: tokio::sync::oneshot::Receiver<Duration>,
) {
    let listener = match tokio::net::TcpListener::from_std(listener) {
        Ok(l) => l,
        Err(e) => {
            tracing::warn!("live view: {e}");
            return;
        }
    };
    let mut tasks = tokio::task::JoinSet::new();
    let drain = loop {
        tokio::select! {
            d = &mut stop => break d.unwrap_or(Duration::ZERO),
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    if tasks.len() >= shared.opts.max_clients {
                        shared.stats.clients_refused.fetch_add(1, Ordering::Relaxed);
                        tracing::info!("live view: {peer} refused: {} connections served", tasks.len());
                        drop(stream);
                        continue;
                    }
                    tasks.spawn(client(stream, peer, shared.clone()));
                }
                Err(e) => {
                    tracing::debug!("live view: accept: {e}");
                    // Out of descriptors and the like: do not spin.
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            },
            Some(_) = tasks.join_next(), if !tasks.is_empty() => {}
        }
    };
    drop(listener);
    // Wait for the clients to write their queues: until all are done, `drain` is over, or no
    // message was written for DRAIN_STALL (only clients that stopped reading are left).
    let deadline = tokio::time::Instant::now() + drain;
    let mut sent = shared.stats.messages_sent.load(Ordering::Relaxed);
    let mut progress_at = tokio::time::Instant::now();
    while !tasks.is_empty() && tokio::time::Instant::now() < deadline {
        let _ = tokio::time::timeout(Duration::from_millis(20), tasks.join_next()).await;
        let now_sent = shared.stats.messages_sent.load(Ordering::Relaxed);
        if now_sent != sent {
            sent = now_sent;
            progress_at = tokio::time::Instant::now();
        } else if progress_at.elapsed() >= DRAIN_STALL {
            break;
        }
    }
}

/// Accepts the handshake only with the Foxglove subprotocol, and selects it.
#[allow(clippy::result_large_err)] // the handshake callback's signature
fn select_subprotocol(req: &Request, mut resp: Response) -> Result<Response, ErrorResponse> {
    let offered = req
        .headers()
        .get_all("sec-websocket-protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim() == SUBPROTOCOL);
    if !offered {
        let mut e = ErrorResponse::new(Some(format!(
            "expected the WebSocket subprotocol {SUBPROTOCOL}"
        )));
        *e.status_mut() = StatusCode::BAD_REQUEST;
        return Err(e);
    }
    resp.headers_mut().insert(
        "sec-websocket-protocol",
        HeaderValue::from_static(SUBPROTOCOL),
    );
    Ok(resp)
}

/// The `messageData` frame of one queued message.
fn message_data(q: &Queued) -> Vec<u8> {
    let mut frame = Vec::with_capacity(13 + q.payload.len());
    frame.push(OP_MESSAGE_DATA);
    frame.extend_from_slice(&q.subscription.to_le_bytes());
    frame.extend_from_slice(&q.log_time_ns.to_le_bytes());
    frame.extend_from_slice(&q.payload);
    frame
}

/// One client connection, from handshake to close.
async fn client(stream: tokio::net::TcpStream, peer: SocketAddr, shared: Arc<Shared>) {
    let stats = shared.stats.clone();
    let _ = stream.set_nodelay(true);
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_CLIENT_MESSAGE))
        .max_frame_size(Some(MAX_CLIENT_MESSAGE));
    let handshake =
        tokio_tungstenite::accept_hdr_async_with_config(stream, select_subprotocol, Some(config));
    let ws = match tokio::time::timeout(HANDSHAKE_TIMEOUT, handshake).await {
        Ok(Ok(ws)) => ws,
        Ok(Err(e)) => {
            stats.handshakes_failed.fetch_add(1, Ordering::Relaxed);
            tracing::info!("live view: {peer}: handshake failed: {e}");
            return;
        }
        Err(_) => {
            stats.handshakes_failed.fetch_add(1, Ordering::Relaxed);
            tracing::info!("live view: {peer}: no handshake within {HANDSHAKE_TIMEOUT:?}");
            return;
        }
    };
    let (data_tx, mut data_rx) = mpsc::channel::<Queued>(shared.opts.queue_messages);
    let (control_tx, mut control_rx) = mpsc::unbounded_channel::<String>();
    let counters = Arc::new(ClientCounters::default());
    let id = {
        let mut st = shared.state();
        if st.closing {
            return;
        }
        let id = st.next_client;
        st.next_client += 1;
        // Registered under the lock that `add_channel` takes: every channel is advertised
        // exactly once to this client, here or later.
        let info = json!({
            "op": "serverInfo",
            "name": shared.opts.name,
            "capabilities": [],
            "supportedEncodings": [],
            "metadata": {},
            "sessionId": shared.session_id,
        });
        let _ = control_tx.send(info.to_string());
        let _ = control_tx.send(json!({"op": "advertise", "channels": st.channels}).to_string());
        st.connected.push((id, peer, counters.clone()));
        st.clients.push(ClientSlot {
            id,
            subscriptions: Vec::new(),
            data: data_tx,
            control: control_tx,
            counters: counters.clone(),
        });
        id
    };
    stats.clients_total.fetch_add(1, Ordering::Relaxed);
    stats.clients_connected.fetch_add(1, Ordering::Relaxed);
    tracing::info!("live view: client {peer} connected");

    let (mut sink, mut incoming) = ws.split();
    let writer = async {
        let (mut control_open, mut data_open) = (true, true);
        while control_open || data_open {
            tokio::select! {
                biased;
                c = control_rx.recv(), if control_open => match c {
                    Some(text) => sink.send(Message::text(text)).await?,
                    None => control_open = false,
                },
                d = data_rx.recv(), if data_open => match d {
                    Some(q) => {
                        counters.queued_bytes.fetch_sub(q.payload.len(), Ordering::Relaxed);
                        let frame = message_data(&q);
                        let n = frame.len() as u64;
                        drop(q);
                        sink.send(Message::binary(frame)).await?;
                        counters.sent.fetch_add(1, Ordering::Relaxed);
                        stats.messages_sent.fetch_add(1, Ordering::Relaxed);
                        stats.bytes_sent.fetch_add(n, Ordering::Relaxed);
                    }
                    None => data_open = false,
                },
            }
        }
        // The server is closing and this client's queue is written.
        sink.close().await
    };
    let reader = async {
        while let Some(m) = incoming.next().await {
            match m {
                Ok(Message::Text(t)) => on_request(&shared, id, t.as_str()),
                Ok(Message::Close(_)) | Err(_) => break,
                // Pings are answered by the library; binary client messages need the
                // `clientPublish` capability, which is not offered.
                Ok(_) => {}
            }
        }
    };
    tokio::select! {
        r = writer => if let Err(e) = r { tracing::debug!("live view: {peer}: {e}") },
        _ = reader => {}
    }

    let mut st = shared.state();
    st.clients.retain(|c| c.id != id);
    st.connected.retain(|c| c.0 != id);
    if st.history.len() == CLIENT_HISTORY {
        st.history.pop_front();
    }
    st.history.push_back(ClientStats {
        peer: Some(peer),
        sent: counters.sent.load(Ordering::Relaxed),
        dropped: counters.dropped.load(Ordering::Relaxed),
        connected: false,
    });
    drop(st);
    stats.clients_connected.fetch_sub(1, Ordering::Relaxed);
    tracing::info!(
        "live view: client {peer} left (sent {}, dropped {})",
        counters.sent.load(Ordering::Relaxed),
        counters.dropped.load(Ordering::Relaxed)
    );
}

/// Applies a client's `subscribe` / `unsubscribe`; anything else is ignored.
fn on_request(shared: &Shared, client: u64, text: &str) {
    let Some(req) = ClientRequest::parse(text) else {
        return;
    };
    let mut st = shared.state();
    let n_channels = st.channels.len() as u64;
    if let Some(c) = st.clients.iter_mut().find(|c| c.id == client) {
        req.apply(&mut c.subscriptions, n_channels);
    }
}

/// A client's request of the `foxglove.websocket.v1` protocol that the server acts on.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ClientRequest {
    /// `{"op": "subscribe", "subscriptions": [{"id": SUB, "channelId": CH}, …]}`: (sub, ch)
    /// pairs; entries whose ids are missing or not `u32` are left out.
    Subscribe(Vec<(u32, u32)>),
    /// `{"op": "unsubscribe", "subscriptionIds": [SUB, …]}`.
    Unsubscribe(Vec<u32>),
}

impl ClientRequest {
    /// Requests from clients are limited to this many entries (a client's text message may
    /// be large; what it asks for stays bounded).
    pub const MAX_ENTRIES: usize = 4096;

    /// Parses a client's text message; `None` for anything that is not JSON or not one of
    /// the two requests.
    pub fn parse(text: &str) -> Option<Self> {
        let v = serde_json::from_str::<Value>(text).ok()?;
        let u32_of = |v: &Value| v.as_u64().and_then(|x| u32::try_from(x).ok());
        match v["op"].as_str()? {
            "subscribe" => Some(Self::Subscribe(
                v["subscriptions"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter_map(|s| Some((u32_of(&s["id"])?, u32_of(&s["channelId"])?)))
                    .take(Self::MAX_ENTRIES)
                    .collect(),
            )),
            "unsubscribe" => Some(Self::Unsubscribe(
                v["subscriptionIds"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter_map(u32_of)
                    .take(Self::MAX_ENTRIES)
                    .collect(),
            )),
            _ => None,
        }
    }

    /// Applies the request to a client's subscriptions, `(channel, subscription)` pairs, with
    /// channels `1 ..= n_channels` advertised: a subscription to an unknown channel, to a
    /// channel already subscribed or with a subscription id already in use is ignored, so
    /// each channel and each id appears at most once.
    pub fn apply(&self, subscriptions: &mut Vec<(u32, u32)>, n_channels: u64) {
        match self {
            Self::Subscribe(list) => {
                for &(sub, ch) in list {
                    let known = ch >= 1 && u64::from(ch) <= n_channels;
                    let taken = subscriptions.iter().any(|&(c2, s2)| c2 == ch || s2 == sub);
                    if known && !taken {
                        subscriptions.push((ch, sub));
                    }
                }
            }
            Self::Unsubscribe(ids) => {
                for sub in ids {
                    subscriptions.retain(|&(_, s2)| s2 != *sub);
                }
            }
        }
    }
}

/// Standard base64 (RFC 4648 §4, with padding).
pub fn base64(data: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_test_vectors() {
        // RFC 4648 §10.
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64(plain.as_bytes()), encoded, "{plain:?}");
        }
        // 6-bit groups 0, 1, …, 11 (hand-packed), and the two last alphabet letters.
        let bytes = [0x00, 0x10, 0x83, 0x10, 0x51, 0x87, 0x20, 0x92, 0x8b];
        assert_eq!(base64(&bytes), "ABCDEFGHIJKL");
        assert_eq!(base64(&[0xfb, 0xff, 0xbf]), "+/+/");
    }

    #[test]
    fn client_requests_parse_and_apply() {
        let sub = ClientRequest::parse(
            r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":1},{"id":2,"channelId":3},{"id":4294967296,"channelId":2},{"id":5}]}"#,
        );
        assert_eq!(sub, Some(ClientRequest::Subscribe(vec![(1, 1), (2, 3)])));
        assert_eq!(ClientRequest::parse("not json"), None);
        assert_eq!(ClientRequest::parse(r#"{"op":"advertise"}"#), None);
        assert_eq!(
            ClientRequest::parse(r#"{"op":"unsubscribe","subscriptionIds":[2,-1,"x"]}"#),
            Some(ClientRequest::Unsubscribe(vec![2]))
        );
        // Two channels advertised: channel 3 is unknown; a channel or an id in use is refused.
        let mut subs = Vec::new();
        sub.unwrap().apply(&mut subs, 2);
        assert_eq!(subs, vec![(1, 1)]);
        ClientRequest::Subscribe(vec![(1, 2), (7, 1), (8, 2)]).apply(&mut subs, 2);
        assert_eq!(subs, vec![(1, 1), (2, 8)]);
        ClientRequest::Unsubscribe(vec![1, 99]).apply(&mut subs, 2);
        assert_eq!(subs, vec![(2, 8)]);
        // A request's entries are bounded.
        let many: Vec<String> = (0..10_000)
            .map(|i| format!(r#"{{"id":{i},"channelId":1}}"#))
            .collect();
        let text = format!(
            r#"{{"op":"subscribe","subscriptions":[{}]}}"#,
            many.join(",")
        );
        match ClientRequest::parse(&text) {
            Some(ClientRequest::Subscribe(v)) => assert_eq!(v.len(), ClientRequest::MAX_ENTRIES),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn message_data_frame_layout() {
        let q = Queued {
            subscription: 0x0403_0201,
            log_time_ns: 0x0c0b_0a09_0807_0605,
            payload: Arc::from(&b"xyz"[..]),
        };
        assert_eq!(
            message_data(&q),
            [1, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, b'x', b'y', b'z']
        );
    }
}
