//! `listen --serve ADDR`: every sweep published live over the Foxglove WebSocket protocol
//! (`foxglove.PointCloud` on the same topics as the MCAP file), with the foxglove SDK's server.
//!
//! The server runs on its own tokio runtime (threads made by the SDK), so clients never slow
//! the receive tasks; a sweep is encoded only while a client is subscribed to its topic.

use std::collections::HashMap;
use std::net::SocketAddr;

use foxglove::messages::packed_element_field::NumericType;
use foxglove::messages::{PackedElementField, PointCloud, Timestamp};
use foxglove::{Channel, WebSocketServer, WebSocketServerHandle};
use ringscan::sweep::Sweep;

use super::run::SweepTap;

/// The running server; dropping it leaves the server running until the process ends.
pub struct LiveView {
    /// The SDK's handle.
    pub handle: WebSocketServerHandle,
}

/// Starts the server on `addr` (port 0: any free port). Call outside any async context.
pub fn start(addr: SocketAddr) -> Result<LiveView, String> {
    let handle = WebSocketServer::new()
        .name(format!("ringscan {}", env!("CARGO_PKG_VERSION")))
        .bind(addr.ip().to_string(), addr.port())
        .start_blocking()
        .map_err(|e| format!("--serve {addr}: {e}"))?;
    Ok(LiveView { handle })
}

fn field(name: &str, offset: u32, ty: NumericType) -> PackedElementField {
    PackedElementField {
        name: name.into(),
        offset,
        r#type: ty as i32,
    }
}

/// The point record's fields (DESIGN.md "Points"), 24-byte stride.
fn fields() -> Vec<PackedElementField> {
    vec![
        field("x", 0, NumericType::Float32),
        field("y", 4, NumericType::Float32),
        field("z", 8, NumericType::Float32),
        field("intensity", 12, NumericType::Float32),
        field("t", 16, NumericType::Uint32),
        field("ring", 20, NumericType::Uint16),
        field("return", 22, NumericType::Uint8),
    ]
}

/// A sweep tap publishing each sweep on its points topic (channels made on first use).
pub fn tap() -> SweepTap {
    let mut channels: HashMap<String, Channel<PointCloud>> = HashMap::new();
    let fields = fields();
    Box::new(move |name: &str, topic: &str, sweep: &Sweep| {
        let ch = channels
            .entry(topic.to_string())
            .or_insert_with(|| Channel::new(topic));
        if !ch.has_sinks() {
            return;
        }
        let ts = sweep.timestamp_ns.max(0) as u64;
        let msg = PointCloud {
            timestamp: Some(Timestamp::new(
                (ts / 1_000_000_000).min(u64::from(u32::MAX)) as u32,
                (ts % 1_000_000_000) as u32,
            )),
            frame_id: name.to_string(),
            pose: None,
            point_stride: 24,
            fields: fields.clone(),
            data: foxglove::bytes::Bytes::copy_from_slice(bytemuck::cast_slice(&sweep.points)),
        };
        ch.log_with_time(&msg, sweep.last_host_ns.max(0) as u64);
    })
}
