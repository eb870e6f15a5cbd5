//! `listen --configure` for Livox sensors that stream only once the host has configured them:
//! the sockets, timeouts and retries around the pure frames of
//! [`crate::sensor::livox::control`].
//!
//! SDK2 (MID-360, HAP): discovery (to port 56000 of `--device-ip`, default the `--sensor`
//! address; a broadcast address works too), then one parameter configuration: point and IMU
//! destination (this host, the ports `listen` bound), IMU on, work mode "sampling". SDK1
//! (Mid-40/70, Horizon, Tele-15, Avia): the device's broadcast on port 55000, the handshake,
//! start sampling, then a heartbeat every second on a thread of its own until `listen` stops
//! (then stop sampling and disconnect). Every request waits [`ACK_WAIT`] for its ACK and is
//! sent at most [`ATTEMPTS`] times; a refusal is an error that names the return code. A device
//! that stops answering the heartbeat is a warning and a count in the summary, not an error:
//! the heartbeat goes on and the device is back when it answers again.

use std::collections::BTreeSet;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde_json::{json, Value};

use super::run::RunError;
use crate::sensor::livox::control as c;
use crate::sensor::livox::{LivoxModel, Protocol};

/// How long one request waits for its ACK.
pub const ACK_WAIT: Duration = Duration::from_secs(1);
/// Times a request is sent before giving up.
pub const ATTEMPTS: u32 = 3;
/// How long the SDK1 host waits for the device's broadcast (it broadcasts every second).
pub const BROADCAST_WAIT: Duration = Duration::from_secs(5);
/// SDK1 heartbeat period (the protocol asks for one at least every second).
pub const HEARTBEAT: Duration = Duration::from_millis(1000);
/// Without an answer for this long, an SDK1 device counts as lost (Livox-SDK drops it after
/// 3 s without a heartbeat answer).
pub const LOST_AFTER: Duration = Duration::from_secs(3);

/// `listen --configure` options.
#[derive(Debug, Clone, Default)]
pub struct ConfigureArgs {
    /// Where the commands go (default: the first `--sensor` address).
    pub device_ip: Option<Ipv4Addr>,
    /// Host port the commands are sent from (default: SDK2 the model's documented host
    /// command port, 56101 for the MID-360 and 56000 for the HAP; SDK1 any free port, which
    /// the handshake names).
    pub control_port: Option<u16>,
}

/// A configured sensor: the SDK1 heartbeat thread, and what to report.
pub struct Configured {
    summary: Value,
    heartbeat: Option<(Arc<AtomicBool>, JoinHandle<Value>)>,
}

impl Drop for Configured {
    /// A run that ends on an error stops the heartbeat too.
    fn drop(&mut self) {
        if let Some((stop, _)) = &self.heartbeat {
            stop.store(true, Ordering::Relaxed);
        }
    }
}

impl Configured {
    /// Stops the heartbeat (SDK1: stop sampling, disconnect) and returns the summary.
    pub fn finish(mut self) -> Value {
        let mut s = std::mem::take(&mut self.summary);
        if let Some((stop, t)) = self.heartbeat.take() {
            stop.store(true, Ordering::Relaxed);
            if let Ok(hb) = t.join() {
                if let Some(o) = s.as_object_mut() {
                    o.insert("heartbeat".into(), hb);
                }
            }
        }
        s
    }
}

fn live(msg: String) -> RunError {
    RunError::Live(format!("--configure: {msg}"))
}

/// The host address the device reaches us at: the `--interface` address if one is given, else
/// the local address the routing table picks for the device (a UDP connect sends nothing).
fn host_ip(interface: Ipv4Addr, device: Ipv4Addr) -> Ipv4Addr {
    if !interface.is_unspecified() {
        return interface;
    }
    let local = UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))
        .and_then(|s| s.connect((device, 9)).map(|()| s))
        .and_then(|s| s.local_addr());
    match local {
        Ok(std::net::SocketAddr::V4(a)) if !a.ip().is_unspecified() => *a.ip(),
        _ => Ipv4Addr::LOCALHOST,
    }
}

/// The host ports the points and the IMU samples go to: the model's own when `listen` bound
/// them, else the `--sensor` ports in order (points to the first, IMU to the second, or the
/// first again).
pub fn dest_ports(model: LivoxModel, bound: &BTreeSet<u16>) -> (u16, u16) {
    let p = model.point_port();
    let i = model.imu_port().unwrap_or(p);
    if bound.contains(&p) {
        return (p, if bound.contains(&i) { i } else { p });
    }
    let mut it = bound.iter().copied();
    let first = it.next().unwrap_or(p);
    (first, it.next().unwrap_or(first))
}

fn bind(interface: Ipv4Addr, port: u16) -> Result<UdpSocket, RunError> {
    let s = UdpSocket::bind((interface, port))
        .map_err(|e| live(format!("binding UDP {interface}:{port}: {e}")))?;
    let _ = s.set_broadcast(true);
    Ok(s)
}

/// Sends `frame` to `to` and waits for the datagram `accept` takes (from `from` when known);
/// at most [`ATTEMPTS`] times.
fn request<T>(
    sock: &UdpSocket,
    to: SocketAddrV4,
    frame: &[u8],
    what: &str,
    mut accept: impl FnMut(&[u8]) -> Option<T>,
) -> Result<T, RunError> {
    let mut buf = [0u8; 2048];
    for attempt in 1..=ATTEMPTS {
        sock.send_to(frame, to)
            .map_err(|e| live(format!("{what}: sending to {to}: {e}")))?;
        let deadline = Instant::now() + ACK_WAIT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            let _ = sock.set_read_timeout(Some(left));
            match sock.recv_from(&mut buf) {
                Ok((n, _)) => {
                    if let Some(t) = accept(&buf[..n]) {
                        return Ok(t);
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    break
                }
                // An ICMP port unreachable of the previous send: nothing listens there yet.
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
                Err(e) => return Err(live(format!("{what}: receiving: {e}"))),
            }
        }
        tracing::warn!("{what}: no answer from {to} (attempt {attempt} of {ATTEMPTS})");
    }
    Err(live(format!(
        "{what}: {to} did not answer ({ATTEMPTS} attempts, {} ms each)",
        ACK_WAIT.as_millis()
    )))
}

/// Configures the sensor at `device` (the model from `--model`, or for SDK2 from discovery)
/// to stream to the `bound` ports of this host.
pub fn configure(
    args: &ConfigureArgs,
    named: Option<LivoxModel>,
    device: Ipv4Addr,
    interface: Ipv4Addr,
    bound: &BTreeSet<u16>,
) -> Result<Configured, RunError> {
    let device = args.device_ip.unwrap_or(device);
    match named.map(LivoxModel::protocol) {
        Some(Protocol::Sdk1) => configure_sdk1(args, named, device, interface, bound),
        _ => configure_sdk2(args, named, device, interface, bound),
    }
}

fn configure_sdk2(
    args: &ConfigureArgs,
    named: Option<LivoxModel>,
    device: Ipv4Addr,
    interface: Ipv4Addr,
    bound: &BTreeSet<u16>,
) -> Result<Configured, RunError> {
    // Without --model, the MID-360's default: discovery tells the model only afterwards.
    let port = args
        .control_port
        .or_else(|| named.and_then(LivoxModel::sdk2_host_command_port))
        .or(LivoxModel::Mid360.sdk2_host_command_port())
        .unwrap_or_default();
    let sock = bind(interface, port)?;
    let mut seq = 1u32;
    let to = SocketAddrV4::new(device, c::SDK2_DISCOVERY_PORT);
    let ack = request(&sock, to, &c::sdk2_discovery(seq), "Livox discovery", |b| {
        let f = c::sdk2_parse(b).ok()?;
        (f.cmd_id == c::cmd::DISCOVERY && f.cmd_type == 1 && f.seq == seq)
            .then(|| c::sdk2_discovery_ack(f.data).ok())
            .flatten()
    })?;
    if ack.ret_code != 0 {
        return Err(live(format!(
            "Livox discovery: {device} answered {} ({:#04x})",
            c::sdk2_return_name(ack.ret_code),
            ack.ret_code
        )));
    }
    let Some(model) = c::sdk2_model(ack.dev_type) else {
        return Err(live(format!(
            "{device}: device type {} is not a MID-360 or HAP (SDK1 sensors: give --model)",
            ack.dev_type
        )));
    };
    if let Some(n) = named.filter(|n| *n != model) {
        tracing::warn!(
            "{device}: --model {} but the sensor says it is a {}",
            n.id(),
            model.name()
        );
    }
    tracing::info!(
        "{device}: {} serial {} found, commands to port {}",
        model.name(),
        ack.serial_str(),
        ack.cmd_port
    );
    let host = host_ip(interface, device);
    let (pp, ip) = dest_ports(model, bound);
    // `sdk2_model` names SDK2 sensors only, each with its ports in the model table.
    let Some((lidar_point, lidar_imu)) = model.sdk2_device_data_ports() else {
        return Err(live(format!(
            "{device}: {} is not an SDK2 sensor",
            model.name()
        )));
    };
    let mut kv = vec![(c::key::POINT_DEST, c::sdk2_dest(host, pp, lidar_point))];
    if model.has_imu() {
        kv.push((c::key::IMU_DEST, c::sdk2_dest(host, ip, lidar_imu)));
        kv.push((c::key::IMU_EN, vec![1]));
    }
    kv.push((c::key::WORK_MODE, vec![c::WORK_MODE_SAMPLING]));
    seq += 1;
    let target = if device.is_broadcast() {
        ack.ip
    } else {
        device
    };
    let to = SocketAddrV4::new(target, ack.cmd_port);
    let (ret, key) = request(
        &sock,
        to,
        &c::sdk2_set_params(seq, &kv),
        "Livox configuration",
        |b| {
            let f = c::sdk2_parse(b).ok()?;
            (f.cmd_id == c::cmd::SET_PARAMS && f.cmd_type == 1 && f.seq == seq)
                .then(|| c::sdk2_params_ack(f.data).ok())
                .flatten()
        },
    )?;
    if ret != 0 {
        return Err(live(format!(
            "{target}: the sensor refused the configuration: {} ({ret:#04x}) on key {key:#06x}",
            c::sdk2_return_name(ret)
        )));
    }
    tracing::info!(
        "{target}: configured: points to {host}:{pp}{}, work mode sampling",
        if model.has_imu() {
            format!(", IMU to {host}:{ip}")
        } else {
            String::new()
        }
    );
    Ok(Configured {
        summary: json!({
            "protocol": "sdk2",
            "device": target.to_string(),
            "model": model.id(),
            "serial": ack.serial_str(),
            "points_to": format!("{host}:{pp}"),
            "imu_to": model.has_imu().then(|| format!("{host}:{ip}")),
        }),
        heartbeat: None,
    })
}

fn configure_sdk1(
    args: &ConfigureArgs,
    named: Option<LivoxModel>,
    device: Ipv4Addr,
    interface: Ipv4Addr,
    bound: &BTreeSet<u16>,
) -> Result<Configured, RunError> {
    // The device's broadcast.
    let bsock = bind(interface, c::SDK1_BROADCAST_PORT)?;
    let deadline = Instant::now() + BROADCAST_WAIT;
    let mut buf = [0u8; 2048];
    let (bc, from) = loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(live(format!(
                "no Livox broadcast from {device} on UDP port {} within {} s",
                c::SDK1_BROADCAST_PORT,
                BROADCAST_WAIT.as_secs()
            )));
        }
        let _ = bsock.set_read_timeout(Some(left));
        let Ok((n, std::net::SocketAddr::V4(src))) = bsock.recv_from(&mut buf) else {
            continue;
        };
        if !device.is_broadcast() && *src.ip() != device {
            continue;
        }
        if let Some(b) = c::sdk1_parse(&buf[..n])
            .ok()
            .and_then(|f| c::sdk1_broadcast(&f))
        {
            break (b, src);
        }
    };
    drop(bsock);
    let dev = *from.ip();
    let model = match (named, c::sdk1_model(bc.dev_type)) {
        (Some(n), Some(m)) if n != m => {
            tracing::warn!(
                "{dev}: --model {} but the sensor says it is a {}",
                n.id(),
                m.name()
            );
            n
        }
        (Some(n), _) => n,
        (None, Some(m)) => m,
        (None, None) => {
            return Err(live(format!(
                "{dev}: device type {} is not a Livox lidar this handles",
                bc.dev_type
            )))
        }
    };
    tracing::info!("{dev}: {} {} broadcasting", model.name(), bc.code_str());
    let sock = bind(interface, args.control_port.unwrap_or(0))?;
    let cmd_port = match sock.local_addr() {
        Ok(std::net::SocketAddr::V4(a)) => a.port(),
        _ => return Err(live("control socket has no IPv4 address".into())),
    };
    let host = host_ip(interface, dev);
    let (dp, ip) = dest_ports(model, bound);
    let to = SocketAddrV4::new(dev, c::SDK1_DEVICE_CMD_PORT);
    let mut seq: u16 = 1;
    sdk1_command(
        &sock,
        to,
        seq,
        &c::sdk1_handshake(seq, host, dp, cmd_port, ip),
        c::sdk1_cmd::HANDSHAKE,
        "handshake",
    )?;
    seq += 1;
    sdk1_command(
        &sock,
        to,
        seq,
        &c::sdk1_sampling(seq, true),
        c::sdk1_cmd::SAMPLING,
        "start sampling",
    )?;
    tracing::info!(
        "{dev}: handshake done, sampling: points to {host}:{dp}, IMU to {host}:{ip}, commands at {cmd_port}"
    );
    let stop = Arc::new(AtomicBool::new(false));
    let t = {
        let stop = stop.clone();
        std::thread::Builder::new()
            .name("ringscan-livox-heartbeat".into())
            .spawn(move || heartbeat(sock, to, seq + 1, &stop))
            .map_err(|e| live(format!("starting the heartbeat thread: {e}")))?
    };
    Ok(Configured {
        summary: json!({
            "protocol": "sdk1",
            "device": dev.to_string(),
            "model": model.id(),
            "broadcast_code": bc.code_str(),
            "points_to": format!("{host}:{dp}"),
            "imu_to": format!("{host}:{ip}"),
        }),
        heartbeat: Some((stop, t)),
    })
}

/// Sends an SDK1 command (`frame`, sequence `seq`) and waits for its ACK (`cmd`): an error
/// naming the return code when the device refuses.
fn sdk1_command(
    sock: &UdpSocket,
    to: SocketAddrV4,
    seq: u16,
    frame: &[u8],
    cmd: u8,
    what: &str,
) -> Result<(), RunError> {
    let ret = request(sock, to, frame, &format!("Livox {what}"), |b| {
        let f = c::sdk1_parse(b).ok()?;
        (f.seq == seq).then(|| c::sdk1_ack_code(&f, cmd)).flatten()
    })?;
    if ret != 0 {
        return Err(live(format!(
            "{}: {what} refused: {} ({ret})",
            to.ip(),
            c::sdk1_return_name(ret)
        )));
    }
    Ok(())
}

/// The SDK1 heartbeat: one a second until `stop`, each ACK counted; a device silent for
/// [`LOST_AFTER`] is reported lost (once per silence). Then stop sampling and disconnect.
fn heartbeat(sock: UdpSocket, to: SocketAddrV4, mut seq: u16, stop: &AtomicBool) -> Value {
    let (mut sent, mut acks, mut lost, mut errors) = (0u64, 0u64, 0u64, 0u64);
    let mut last_ack = Instant::now();
    let mut is_lost = false;
    let mut buf = [0u8; 2048];
    let mut next = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        if Instant::now() >= next {
            next += HEARTBEAT;
            match sock.send_to(&c::sdk1_heartbeat(seq), to) {
                Ok(_) => sent += 1,
                Err(_) => errors += 1,
            }
            seq = seq.wrapping_add(1);
        }
        // Short reads, so that a stop is seen within 100 ms.
        let _ = sock.set_read_timeout(Some(Duration::from_millis(100)));
        if let Ok((n, _)) = sock.recv_from(&mut buf) {
            if let Ok(f) = c::sdk1_parse(&buf[..n]) {
                if c::sdk1_ack_code(&f, c::sdk1_cmd::HEARTBEAT).is_some() {
                    acks += 1;
                    last_ack = Instant::now();
                    if is_lost {
                        is_lost = false;
                        tracing::info!("Livox {}: answering the heartbeat again", to.ip());
                    }
                }
            }
        }
        if !is_lost && last_ack.elapsed() >= LOST_AFTER {
            is_lost = true;
            lost += 1;
            tracing::warn!(
                "Livox {}: lost (no heartbeat answer for {} s); still trying",
                to.ip(),
                LOST_AFTER.as_secs()
            );
        }
    }
    let _ = sock.send_to(&c::sdk1_sampling(seq, false), to);
    let _ = sock.send_to(&c::sdk1_disconnect(seq.wrapping_add(1)), to);
    json!({
        "sent": sent,
        "answered": acks,
        "lost": lost,
        "send_errors": errors,
    })
}
