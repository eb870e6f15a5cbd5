//! `listen --multicast GROUP --interface 127.0.0.1`: a sensor sending to a multicast group on
//! the loopback interface is received and decoded like a unicast one.

mod common;
mod listen_util;

use std::net::{Ipv4Addr, SocketAddrV4};

use listen_util::*;
use socket2::{Domain, Protocol, Socket, Type};

#[test]
fn a_sensor_sending_to_a_multicast_group_is_decoded() {
    let Some(c) = common::captures() else { return };
    let _g = serial();
    let pcap = c.join("jerry73204__rust-lidar-utils/test_files/velodyne_example.pcap");
    let dgrams = common::datagrams(&pcap);
    let offset = free_offset(&[2368]);
    let port = (2368 + offset) as u16;
    let group = Ipv4Addr::new(239, 255, 42, 7);
    let l = start_listen(&[
        "--sensor".into(),
        format!("127.0.0.1:{port}"),
        "--multicast".into(),
        group.to_string(),
        "--interface".into(),
        "127.0.0.1".into(),
    ]);
    let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).unwrap();
    s.bind(&SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0).into())
        .unwrap();
    s.set_multicast_if_v4(&Ipv4Addr::LOCALHOST).unwrap();
    s.set_multicast_loop_v4(true).unwrap();
    let to = SocketAddrV4::new(group, port).into();
    for (_, _, payload) in &dgrams {
        s.send_to(payload, &to).unwrap();
        std::thread::sleep(std::time::Duration::from_micros(500));
    }
    std::thread::sleep(std::time::Duration::from_millis(300));
    let (code, out, err) = l.stop("INT");
    assert_eq!(code, Some(0), "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(j["receive"]["datagrams"], dgrams.len(), "{j}");
    assert_eq!(j["receive"]["queue_dropped"], 0);
    assert_eq!(j["receive"]["kernel_dropped"], 0);
    // The golden of this capture (velodyne_decoder): 29,027 + 2,603 points in 2 frames.
    assert_eq!(j["points"], 29_027 + 2_603);
    assert_eq!(j["sweeps"], 2);
}
