//! Edge: live UDP input for `ringscan listen`, and pacing for `ringscan replay`.
//!
//! - [`bind`]: one socket per port (socket2): address reuse, the largest receive buffer the kernel
//!   grants (asked for, then read back), optional multicast membership.
//! - [`receive`]: the receive task (tokio): datagrams from the sensors' addresses go into a
//!   bounded queue with a byte budget; what does not fit, and datagrams from other addresses,
//!   are counted, never waited for.
//! - [`BoundSocket::kernel_drops`]: datagrams the kernel dropped for want of buffer space, read
//!   from the `drops` column of `/proc/net/udp` for the socket's inode (Linux), so no `unsafe`
//!   control-message parsing is needed.
//! - [`http_get`]: a minimal HTTP/1.1 GET (Ouster sensors serve their metadata at
//!   `/api/v1/sensor/metadata`).
//! - [`due_offset`]: when a replayed datagram is due.
//!
//! Knows nothing of packet formats.

use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::Arc;
use std::time::Duration;

use socket2::{Domain, Protocol, Socket, Type};

/// Receive buffer asked for by default: 64 MiB (the kernel grants at most `net.core.rmem_max`).
pub const DEFAULT_RECV_BUFFER: usize = 64 << 20;
/// Largest UDP payload.
pub const MAX_DATAGRAM: usize = 65_535;
/// Largest HTTP response [`http_get`] reads.
pub const MAX_HTTP_RESPONSE: usize = 8 << 20;

/// Errors of the live source.
#[derive(Debug, thiserror::Error)]
pub enum UdpError {
    /// A socket call failed.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The OS error.
        #[source]
        source: io::Error,
    },
    /// An HTTP response that is not a `200` with a body.
    #[error("http://{addr}{path}: {reason}")]
    Http {
        /// Server.
        addr: SocketAddr,
        /// Requested path.
        path: String,
        /// What was wrong.
        reason: String,
    },
}

fn io_err(context: impl Into<String>) -> impl FnOnce(io::Error) -> UdpError {
    let context = context.into();
    move |source| UdpError::Io { context, source }
}

/// How to open one listening socket.
#[derive(Clone, Debug)]
pub struct SocketOptions {
    /// Local port.
    pub port: u16,
    /// Multicast group to join (the socket is bound to the wildcard address).
    pub multicast: Option<Ipv4Addr>,
    /// Interface address for the multicast membership (`0.0.0.0`: the kernel's choice).
    pub interface: Ipv4Addr,
    /// Receive buffer to ask for, bytes.
    pub recv_buffer: usize,
}

/// A bound socket and what the kernel granted.
#[derive(Debug)]
pub struct BoundSocket {
    /// The socket (non-blocking).
    pub socket: std::net::UdpSocket,
    /// Local port.
    pub port: u16,
    /// Receive buffer asked for, bytes.
    pub requested_recv_buffer: usize,
    /// Receive buffer granted, as `SO_RCVBUF` reads back (Linux reports twice the usable size).
    pub granted_recv_buffer: usize,
    inode: Option<u64>,
}

/// Opens a UDP socket on `0.0.0.0:port` with a large receive buffer and, with a multicast
/// group, address reuse and the group membership.
pub fn bind(opts: &SocketOptions) -> Result<BoundSocket, UdpError> {
    let port = opts.port;
    let ctx = |what: &str| format!("UDP port {port}: {what}");
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
        .map_err(io_err(ctx("creating the socket")))?;
    // Several listeners may share a multicast group; a unicast port stays exclusive, so a second
    // listener fails clearly instead of silently splitting the traffic.
    if opts.multicast.is_some() {
        socket
            .set_reuse_address(true)
            .map_err(io_err(ctx("SO_REUSEADDR")))?;
    }
    // Ask for the whole buffer: past net.core.rmem_max where the process may (SO_RCVBUFFORCE,
    // CAP_NET_ADMIN), else SO_RCVBUF, which the kernel silently caps at rmem_max. Read back
    // what was granted.
    if !force_recv_buffer(&socket, opts.recv_buffer) {
        let _ = socket.set_recv_buffer_size(opts.recv_buffer);
    }
    let granted = socket
        .recv_buffer_size()
        .map_err(io_err(ctx("reading SO_RCVBUF")))?;
    socket
        .bind(&SocketAddr::V4(SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, port)).into())
        .map_err(io_err(ctx("binding")))?;
    if let Some(group) = opts.multicast {
        socket
            .join_multicast_v4(&group, &opts.interface)
            .map_err(io_err(ctx(&format!(
                "joining multicast group {group} on {}",
                opts.interface
            ))))?;
    }
    socket
        .set_nonblocking(true)
        .map_err(io_err(ctx("non-blocking mode")))?;
    let socket: std::net::UdpSocket = socket.into();
    let inode = socket_inode(&socket);
    Ok(BoundSocket {
        socket,
        port,
        requested_recv_buffer: opts.recv_buffer,
        granted_recv_buffer: granted,
        inode,
    })
}

#[cfg(target_os = "linux")]
fn force_recv_buffer(socket: &Socket, size: usize) -> bool {
    use nix::sys::socket::{setsockopt, sockopt::RcvBufForce};
    setsockopt(socket, RcvBufForce, &size).is_ok()
}

#[cfg(not(target_os = "linux"))]
fn force_recv_buffer(_: &Socket, _: usize) -> bool {
    false
}

/// `net.core.rmem_max`, the largest receive buffer an unprivileged socket may ask for (Linux).
pub fn rmem_max() -> Option<usize> {
    std::fs::read_to_string("/proc/sys/net/core/rmem_max")
        .ok()?
        .trim()
        .parse()
        .ok()
}

#[cfg(target_os = "linux")]
fn socket_inode(s: &std::net::UdpSocket) -> Option<u64> {
    use std::os::fd::AsRawFd;
    let link = std::fs::read_link(format!("/proc/self/fd/{}", s.as_raw_fd())).ok()?;
    let l = link.to_str()?;
    l.strip_prefix("socket:[")?.strip_suffix(']')?.parse().ok()
}

#[cfg(not(target_os = "linux"))]
fn socket_inode(_: &std::net::UdpSocket) -> Option<u64> {
    None
}

impl BoundSocket {
    /// Datagrams the kernel dropped on this socket (receive buffer full), where Linux reports
    /// them; `None` elsewhere.
    pub fn kernel_drops(&self) -> Option<u64> {
        let inode = self.inode?;
        let text = std::fs::read_to_string("/proc/net/udp").ok()?;
        proc_net_udp_drops(&text, inode)
    }
}

/// The `drops` column of the `/proc/net/udp` row whose `inode` column is `inode`.
pub fn proc_net_udp_drops(text: &str, inode: u64) -> Option<u64> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next()?.split_whitespace().collect();
    // The header names "tx_queue rx_queue" and "tr tm->when" as two columns each, while rows
    // join them with ':'; the inode and drops columns are found from the end of the header.
    let drops_col = header.iter().position(|h| *h == "drops")?;
    let inode_col = header.iter().position(|h| *h == "inode")?;
    let from_end_drops = header.len() - drops_col;
    let from_end_inode = header.len() - inode_col;
    for line in lines {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < from_end_drops.max(from_end_inode) {
            continue;
        }
        let ino: Option<u64> = f[f.len() - from_end_inode].parse().ok();
        if ino == Some(inode) {
            return f[f.len() - from_end_drops].parse().ok();
        }
    }
    None
}

/// One datagram taken off a socket.
#[derive(Clone, Debug)]
pub struct Received {
    /// Host receive time, ns since the Unix epoch.
    pub time_ns: i64,
    /// Source address.
    pub src: SocketAddrV4,
    /// Local port it arrived on.
    pub port: u16,
    /// Payload.
    pub payload: Vec<u8>,
}

/// Counters of the receive side, shared between the receive tasks and whoever reports them.
#[derive(Debug, Default)]
pub struct ReceiveStats {
    /// Datagrams received from the sensors' addresses.
    pub datagrams: AtomicU64,
    /// Their payload bytes.
    pub bytes: AtomicU64,
    /// Datagrams from other addresses (not queued).
    pub other_source: AtomicU64,
    /// Datagrams that did not fit in the queue (count or byte budget) and were dropped.
    pub queue_dropped: AtomicU64,
    /// Payload bytes in the queue now (the consumer subtracts what it takes).
    pub queued_bytes: AtomicUsize,
    /// Largest `queued_bytes` seen.
    pub queued_bytes_peak: AtomicUsize,
    /// Receive errors other than "would block".
    pub errors: AtomicU64,
}

/// Where received datagrams go.
pub struct Queue {
    /// The bounded channel to the decode thread.
    pub tx: SyncSender<Received>,
    /// Most payload bytes held in the queue at once.
    pub byte_budget: usize,
    /// Shared counters.
    pub stats: Arc<ReceiveStats>,
}

impl Queue {
    /// Queues one datagram, or counts it as dropped; never waits. Returns `false` once the
    /// consumer is gone.
    pub fn offer(&self, r: Received) -> bool {
        let st = &self.stats;
        let len = r.payload.len();
        let now = st.queued_bytes.fetch_add(len, Ordering::Relaxed) + len;
        if now > self.byte_budget {
            st.queued_bytes.fetch_sub(len, Ordering::Relaxed);
            st.queue_dropped.fetch_add(1, Ordering::Relaxed);
            return true;
        }
        st.queued_bytes_peak.fetch_max(now, Ordering::Relaxed);
        match self.tx.try_send(r) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) => {
                st.queued_bytes.fetch_sub(len, Ordering::Relaxed);
                st.queue_dropped.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Disconnected(_)) => {
                st.queued_bytes.fetch_sub(len, Ordering::Relaxed);
                false
            }
        }
    }
}

fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

/// Receives datagrams on `socket` until the queue's consumer is gone: those from `sources`
/// (every address when empty) are queued with their receive time, the rest counted.
pub async fn receive(
    socket: std::net::UdpSocket,
    port: u16,
    sources: Arc<Vec<Ipv4Addr>>,
    queue: Queue,
) -> Result<(), UdpError> {
    let socket = tokio::net::UdpSocket::from_std(socket)
        .map_err(io_err(format!("UDP port {port}: registering with tokio")))?;
    let mut buf = vec![0u8; MAX_DATAGRAM];
    let st = queue.stats.clone();
    loop {
        let (n, from) = match socket.recv_from(&mut buf).await {
            Ok(x) => x,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(_) => {
                // ICMP errors reported on a UDP socket and the like: count, go on.
                st.errors.fetch_add(1, Ordering::Relaxed);
                continue;
            }
        };
        let SocketAddr::V4(src) = from else {
            st.other_source.fetch_add(1, Ordering::Relaxed);
            continue;
        };
        if !sources.is_empty() && !sources.contains(src.ip()) {
            st.other_source.fetch_add(1, Ordering::Relaxed);
            continue;
        }
        st.datagrams.fetch_add(1, Ordering::Relaxed);
        st.bytes.fetch_add(n as u64, Ordering::Relaxed);
        let r = Received {
            time_ns: now_ns(),
            src,
            port,
            payload: buf[..n].to_vec(),
        };
        if !queue.offer(r) {
            return Ok(());
        }
    }
}

/// `GET path` from `addr` over HTTP/1.1 (`Connection: close`); the body of a `200` response
/// (plain or chunked), at most [`MAX_HTTP_RESPONSE`] bytes, within `timeout`.
pub async fn http_get(
    addr: SocketAddr,
    path: &str,
    timeout: Duration,
) -> Result<Vec<u8>, UdpError> {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let herr = |reason: String| UdpError::Http {
        addr,
        path: path.to_string(),
        reason,
    };
    let work = async {
        let mut s = tokio::net::TcpStream::connect(addr)
            .await
            .map_err(|e| herr(format!("connecting: {e}")))?;
        let req = format!(
            "GET {path} HTTP/1.1\r\nHost: {}\r\nAccept: application/json\r\nConnection: close\r\nUser-Agent: ringscan/{}\r\n\r\n",
            addr.ip(),
            env!("CARGO_PKG_VERSION")
        );
        s.write_all(req.as_bytes())
            .await
            .map_err(|e| herr(format!("sending the request: {e}")))?;
        let mut resp = Vec::new();
        let mut chunk = [0u8; 16 * 1024];
        loop {
            let n = s
                .read(&mut chunk)
                .await
                .map_err(|e| herr(format!("reading the response: {e}")))?;
            if n == 0 {
                break;
            }
            if resp.len() + n > MAX_HTTP_RESPONSE {
                return Err(herr(format!(
                    "response larger than {MAX_HTTP_RESPONSE} bytes"
                )));
            }
            resp.extend_from_slice(&chunk[..n]);
        }
        parse_http_response(&resp).map_err(herr)
    };
    match tokio::time::timeout(timeout, work).await {
        Ok(r) => r,
        Err(_) => Err(herr(format!("no complete response within {timeout:?}"))),
    }
}

/// The body of a complete HTTP/1.x response, if its status is 200.
pub fn parse_http_response(resp: &[u8]) -> Result<Vec<u8>, String> {
    let head_end = resp
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| format!("no end of headers in {} bytes", resp.len()))?;
    let head = std::str::from_utf8(&resp[..head_end]).map_err(|_| "headers not UTF-8")?;
    let mut lines = head.split("\r\n");
    let status = lines.next().unwrap_or("");
    let mut parts = status.splitn(3, ' ');
    let version = parts.next().unwrap_or("");
    let code = parts.next().unwrap_or("");
    if !version.starts_with("HTTP/1.") {
        return Err(format!("not an HTTP/1.x status line: {status:?}"));
    }
    if code != "200" {
        return Err(format!("status {status:?}"));
    }
    let mut chunked = false;
    let mut length: Option<usize> = None;
    for l in lines {
        let Some((k, v)) = l.split_once(':') else {
            continue;
        };
        let (k, v) = (k.trim().to_ascii_lowercase(), v.trim());
        if k == "transfer-encoding" && v.to_ascii_lowercase().contains("chunked") {
            chunked = true;
        } else if k == "content-length" {
            length = Some(v.parse().map_err(|_| format!("Content-Length {v:?}"))?);
        }
    }
    let body = &resp[head_end + 4..];
    if chunked {
        return dechunk(body);
    }
    match length {
        Some(n) if body.len() < n => Err(format!(
            "body of {} bytes, Content-Length says {n}",
            body.len()
        )),
        Some(n) => Ok(body[..n].to_vec()),
        None => Ok(body.to_vec()),
    }
}

fn dechunk(mut body: &[u8]) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    loop {
        let line_end = body
            .windows(2)
            .position(|w| w == b"\r\n")
            .ok_or("chunk size line without CRLF")?;
        let line = std::str::from_utf8(&body[..line_end]).map_err(|_| "chunk size not text")?;
        let size_hex = line.split(';').next().unwrap_or("").trim();
        let size =
            usize::from_str_radix(size_hex, 16).map_err(|_| format!("chunk size {size_hex:?}"))?;
        body = &body[line_end + 2..];
        if size == 0 {
            return Ok(out);
        }
        // `size` comes from the peer: compare without adding to it (a size near usize::MAX
        // must not wrap around).
        if body.len() < 2 || body.len() - 2 < size {
            return Err(format!("chunk of {size} bytes cut short"));
        }
        out.extend_from_slice(&body[..size]);
        body = &body[size + 2..];
    }
}

/// Replay speed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rate {
    /// Capture time divided by this factor (1.0 = real time).
    Factor(f64),
    /// As fast as the sockets take them.
    Max,
}

/// When a datagram captured `since_first_ns` after the first one is due, from the replay's
/// start; `None` for [`Rate::Max`].
pub fn due_offset(since_first_ns: i64, rate: Rate) -> Option<Duration> {
    match rate {
        Rate::Max => None,
        Rate::Factor(f) => {
            let ns = since_first_ns.max(0) as f64 / f;
            Some(Duration::from_nanos(ns.min(u64::MAX as f64) as u64))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drops_column_is_found_by_inode() {
        // Layout of Linux's /proc/net/udp (header and rows as the kernel prints them).
        let text = "   sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode ref pointer drops            \n\
  126: 00000000:0940 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 41234 2 0000000000000000 17        \n\
  127: 0100007F:1D4E 00000000:0000 07 00000000:00000000 00:00000000 00000000     0        0 41299 2 0000000000000000 0         \n";
        assert_eq!(proc_net_udp_drops(text, 41234), Some(17));
        assert_eq!(proc_net_udp_drops(text, 41299), Some(0));
        assert_eq!(proc_net_udp_drops(text, 1), None);
        assert_eq!(proc_net_udp_drops("", 1), None);
    }

    #[test]
    fn http_bodies_plain_sized_and_chunked() {
        let plain = b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\n\r\nhello";
        assert_eq!(parse_http_response(plain).unwrap(), b"hello");
        let chunked =
            b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n4\r\nWiki\r\n5;x=1\r\npedia\r\n0\r\n\r\n";
        assert_eq!(parse_http_response(chunked).unwrap(), b"Wikipedia");
        let not_found = b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n";
        assert!(parse_http_response(not_found).unwrap_err().contains("404"));
        let short = b"HTTP/1.1 200 OK\r\nContent-Length: 9\r\n\r\nhello";
        assert!(parse_http_response(short).is_err());
        assert!(parse_http_response(b"garbage").is_err());
        let bad_chunk = b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n";
        assert!(parse_http_response(bad_chunk).is_err());
        // A peer's chunk size near usize::MAX is an error, not an overflow.
        let huge =
            b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\nffffffffffffffff\r\nab\r\n";
        assert!(parse_http_response(huge).unwrap_err().contains("cut short"));
    }

    #[test]
    fn pacing_divides_capture_time_by_the_rate() {
        assert_eq!(
            due_offset(1_000_000_000, Rate::Factor(1.0)),
            Some(Duration::from_secs(1))
        );
        assert_eq!(
            due_offset(1_000_000_000, Rate::Factor(10.0)),
            Some(Duration::from_millis(100))
        );
        assert_eq!(due_offset(-5, Rate::Factor(1.0)), Some(Duration::ZERO));
        assert_eq!(due_offset(5, Rate::Max), None);
    }

    #[test]
    fn queue_counts_what_does_not_fit() {
        let (tx, rx) = std::sync::mpsc::sync_channel(2);
        let stats = Arc::new(ReceiveStats::default());
        let q = Queue {
            tx,
            byte_budget: 250,
            stats: stats.clone(),
        };
        let r = |n: usize| Received {
            time_ns: 0,
            src: SocketAddrV4::new(Ipv4Addr::LOCALHOST, 1),
            port: 2,
            payload: vec![0; n],
        };
        assert!(q.offer(r(100)));
        assert!(q.offer(r(100)));
        // Byte budget: 300 > 250.
        assert!(q.offer(r(100)));
        assert_eq!(stats.queue_dropped.load(Ordering::Relaxed), 1);
        // Count: the channel holds 2.
        assert!(q.offer(r(10)));
        assert_eq!(stats.queue_dropped.load(Ordering::Relaxed), 2);
        assert_eq!(stats.queued_bytes.load(Ordering::Relaxed), 200);
        drop(rx);
        assert!(!q.offer(r(1)));
    }

    #[test]
    fn bound_socket_reports_its_buffer_and_zero_drops() {
        let s = bind(&SocketOptions {
            port: 0,
            multicast: None,
            interface: Ipv4Addr::UNSPECIFIED,
            recv_buffer: 1 << 20,
        })
        .unwrap();
        assert!(s.granted_recv_buffer > 0);
        if cfg!(target_os = "linux") {
            assert_eq!(s.kernel_drops(), Some(0));
        }
    }
}
