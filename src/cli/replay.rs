//! `ringscan replay`: a capture's UDP payloads sent again, each to its original destination
//! port (+ an offset), paced by the capture's own timestamps.

use std::collections::HashMap;
use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use crate::source::udp::{due_offset, Rate};
use serde_json::json;

use super::bag_args::{self as input, BagArgs, Input};
use super::run::RunError;

/// Everything `replay` needs.
#[derive(Debug, Clone)]
pub struct ReplayArgs {
    pub input: PathBuf,
    pub to: Ipv4Addr,
    pub port_offset: i32,
    pub rate: Rate,
    /// Times the capture is sent (≥ 1).
    pub loops: u32,
    /// Send each original source's datagrams from its own loopback address 127.0.0.k.
    pub per_source_loopback: bool,
    /// Stop sending after this long.
    pub duration: Option<Duration>,
    pub json: bool,
    /// `--topic`, `--start`, `--end` (bags).
    pub bag: BagArgs,
}

/// Parses `--rate`: a positive factor or `max`.
pub fn parse_rate(s: &str) -> Result<Rate, String> {
    if s.eq_ignore_ascii_case("max") {
        return Ok(Rate::Max);
    }
    match s.parse::<f64>() {
        Ok(f) if f.is_finite() && f > 0.0 => Ok(Rate::Factor(f)),
        _ => Err(format!(
            "`{s}`: expected a positive factor (1.0 = real time) or `max`"
        )),
    }
}

/// Sockets, one per sending address.
struct Senders {
    per_source: bool,
    /// Bind to the source address itself (a bag's or recording's sensors already come from
    /// 127.0.0.N).
    exact: bool,
    sockets: Vec<UdpSocket>,
    by_source: HashMap<Ipv4Addr, usize>,
}

impl Senders {
    fn socket_for(&mut self, src: Ipv4Addr) -> Result<&UdpSocket, RunError> {
        let key = if self.per_source {
            src
        } else {
            Ipv4Addr::UNSPECIFIED
        };
        let idx = match self.by_source.get(&key) {
            Some(&i) => i,
            None => {
                let k = self.sockets.len();
                let local = if self.per_source {
                    if k >= 254 {
                        return Err(RunError::Usage(
                            "--per-source-loopback: more than 254 source addresses".into(),
                        ));
                    }
                    if self.exact {
                        src
                    } else {
                        Ipv4Addr::new(127, 0, 0, k as u8 + 1)
                    }
                } else {
                    Ipv4Addr::UNSPECIFIED
                };
                let s = UdpSocket::bind(SocketAddrV4::new(local, 0)).map_err(|e| {
                    RunError::Usage(format!("binding a sending socket to {local}: {e}"))
                })?;
                let _ = s.set_broadcast(true);
                if self.per_source {
                    tracing::info!("source {src} is sent from {local}");
                }
                self.sockets.push(s);
                self.by_source.insert(key, k);
                k
            }
        };
        Ok(&self.sockets[idx])
    }
}

/// `ringscan replay`.
pub fn replay_command(args: &ReplayArgs) -> Result<ExitCode, RunError> {
    let path_s = args.input.display().to_string();
    let serr = |err: input::InputError| RunError::Source {
        path: path_s.clone(),
        err,
    };
    if args.per_source_loopback && !args.to.is_loopback() {
        return Err(RunError::Usage(format!(
            "--per-source-loopback sends from 127.0.0.x: --to must be a loopback address, not {}",
            args.to
        )));
    }
    let mut senders = Senders {
        per_source: args.per_source_loopback,
        exact: false,
        sockets: Vec::new(),
        by_source: HashMap::new(),
    };
    let started = Instant::now();
    let (mut sent, mut bytes, mut errors, mut skipped) = (0u64, 0u64, 0u64, 0u64);
    let mut decoded_frames = 0u64;
    // Where each loop starts on the replay clock.
    let mut loop_base_ns: i64 = 0;
    let mut last_rel_ns: i64 = 0;
    let over = |started: &Instant| args.duration.is_some_and(|d| started.elapsed() >= d);
    // The replay clock's zero: when the first datagram is due. Opening the input (a bag's
    // index, a sqlite3 file) is not replay time; counted in, the first datagrams of each loop
    // went out in a burst at full speed until the schedule caught up, and receivers dropped
    // them.
    let mut zero: Option<Instant> = None;
    'loops: for _ in 0..args.loops.max(1) {
        let opening = Instant::now();
        let mut src = input::open(&args.input, &args.bag)?;
        if let Some(z) = zero.as_mut() {
            *z += opening.elapsed();
        }
        senders.exact = matches!(src, Input::Bag(_) | Input::Lvx(_));
        let mut loop_first: Option<i64> = None;
        while let Some(d) = src.next_datagram().map_err(serr)? {
            if over(&started) {
                break 'loops;
            }
            let lf = *loop_first.get_or_insert(d.time_ns);
            let rel = loop_base_ns + d.time_ns.saturating_sub(lf);
            last_rel_ns = last_rel_ns.max(rel);
            if let Some(due) = due_offset(rel, args.rate) {
                let now = zero.get_or_insert_with(Instant::now).elapsed();
                // Sleep only when worth it; at high rates the small waits are made up in bursts.
                if due > now + Duration::from_micros(200) {
                    // A gap in the capture longer than what is left of --duration ends the
                    // run on time instead of sleeping past it.
                    let left = args.duration.map(|d| d.saturating_sub(started.elapsed()));
                    std::thread::sleep(left.map_or(due - now, |l| l.min(due - now)));
                    if over(&started) {
                        break 'loops;
                    }
                }
            }
            // Data a ROS driver decoded (a bag's points or IMU frames) was never on the wire.
            if crate::sensor::is_decoded_frame(d.payload) {
                decoded_frames += 1;
                continue;
            }
            let port = i32::from(d.dst.port()) + args.port_offset;
            let Ok(port) = u16::try_from(port) else {
                skipped += 1;
                continue;
            };
            let sock = senders.socket_for(*d.src.ip())?;
            match sock.send_to(d.payload, SocketAddrV4::new(args.to, port)) {
                Ok(_) => {
                    sent += 1;
                    bytes += d.payload.len() as u64;
                }
                Err(e) => {
                    errors += 1;
                    if errors <= 3 {
                        tracing::warn!("sending {} bytes to port {port}: {e}", d.payload.len());
                    }
                }
            }
        }
        // The next loop starts one mean packet period after this one ended.
        let period = if sent > 1 {
            last_rel_ns / (sent as i64 - 1).max(1)
        } else {
            0
        };
        loop_base_ns = last_rel_ns + period;
    }
    let elapsed = started.elapsed().as_secs_f64();
    let summary = json!({
        "input": path_s,
        "to": args.to.to_string(),
        "sent": sent,
        "bytes": bytes,
        "send_errors": errors,
        "skipped_port_out_of_range": skipped,
        "skipped_decoded_messages": decoded_frames,
        "sources": senders.by_source.len(),
        "elapsed_s": elapsed,
        "datagrams_per_s": if elapsed > 0.0 { sent as f64 / elapsed } else { 0.0 },
    });
    if args.json {
        outln!("{summary}");
    } else {
        outln!(
            "sent {sent} datagrams ({bytes} bytes) to {} in {elapsed:.3} s; {errors} send errors",
            args.to
        );
        if skipped > 0 {
            outln!(
                "skipped {skipped} datagrams whose port + --port-offset {} is outside 0..=65535",
                args.port_offset
            );
        }
        if decoded_frames > 0 {
            outln!("skipped {decoded_frames} messages a driver had decoded (never on the wire)");
        }
    }
    // A replay that sent nothing did not do its job, whatever the reason.
    if sent == 0 {
        return Err(RunError::Reported(if skipped + errors > 0 {
            format!(
                "no datagram was sent ({skipped} outside the port range with --port-offset {}, \
                 {errors} send errors)",
                args.port_offset
            )
        } else if decoded_frames > 0 {
            format!(
                "no datagram was sent: the input holds no packet, only {decoded_frames} \
                 messages a driver had decoded"
            )
        } else {
            "no datagram was sent: the input holds none (or none within --topic, --start, \
             --end, --duration)"
                .to_string()
        }));
    }
    Ok(ExitCode::SUCCESS)
}
