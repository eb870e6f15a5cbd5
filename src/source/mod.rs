//! Edge: where datagrams come from (pcap / pcapng captures, ROS bags, Livox recordings, live
//! UDP sockets).
//!
//! Knows nothing of packet formats: it yields [`Datagram`]s.

use std::net::SocketAddrV4;

#[cfg(feature = "bag")]
pub mod bag;
#[cfg(all(feature = "pcap", feature = "bag"))]
pub mod input;
pub mod link;
pub mod lvx;
#[cfg(feature = "pcap")]
pub mod pcap;
#[cfg(feature = "pcap")]
pub mod read_ahead;
pub mod reassembly;
#[cfg(feature = "udp")]
pub mod udp;

/// One UDP datagram as it arrived: capture (host) time, addresses, payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Datagram<'a> {
    /// Host receive time (the capture time for pcap), ns since the Unix epoch.
    pub time_ns: i64,
    /// Source address and port.
    pub src: SocketAddrV4,
    /// Destination address and port.
    pub dst: SocketAddrV4,
    /// UDP payload.
    pub payload: &'a [u8],
}
