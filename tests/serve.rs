//! `--serve`: the live view over the Foxglove WebSocket protocol, seen by a WebSocket client.
//!
//! The client here is written from the protocol's specification (foxglove/ws-protocol
//! `docs/spec.md`): it offers the subprotocol `foxglove.websocket.v1`, reads `serverInfo` and
//! `advertise`, subscribes to `/points` and parses the `messageData` frames (opcode 0x01,
//! subscription id u32 LE, log time u64 LE, payload) and their `foxglove.PointCloud` payloads
//! with its own protobuf reader. The truth it compares with: the MCAP file the same run writes
//! (read with the `mcap` crate), whose `/points` messages the live view must reproduce byte for
//! byte, and `decode --json` (sensor name = frame id, sweep and point totals).

mod listen_util;

use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use listen_util::{free_offset, replay, serial, BIN};
use serde_json::Value;
use tungstenite::client::IntoClientRequest;
use tungstenite::protocol::WebSocketConfig;
use tungstenite::{Message, WebSocket};

const SUBPROTOCOL: &str = "foxglove.websocket.v1";

fn demo_pcap() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/demo-vlp16.pcap")
}

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ringscan-serve-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A ringscan process with `--serve 127.0.0.1:0`: its served address (from its log) and its
/// stderr so far.
struct Served {
    child: Child,
    addr: SocketAddr,
    stderr: std::sync::Arc<std::sync::Mutex<String>>,
}

/// Starts `ringscan ARGS` (with `RINGSCAN_LOG=info`) and waits for the live view's address; for
/// `listen`, also for its sockets.
fn start(args: &[String]) -> Served {
    let mut child = Command::new(BIN)
        .args(args)
        .env("RINGSCAN_LOG", "info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn ringscan");
    let listen = args.iter().any(|a| a == "listen");
    let stderr = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
    let (tx, rx) = mpsc::channel::<Option<SocketAddr>>();
    let err = child.stderr.take().expect("stderr");
    let buf = stderr.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            if let Some(at) = line.find("ws://") {
                let addr = line[at + 5..].split_whitespace().next().unwrap_or("");
                let _ = tx.send(addr.parse().ok());
            }
            if line.contains("listening on UDP ports") {
                let _ = tx.send(None);
            }
            let mut b = buf.lock().unwrap();
            b.push_str(&line);
            b.push('\n');
        }
    });
    let started = Instant::now();
    let (mut addr, mut ready) = (None, !listen);
    while addr.is_none() || !ready {
        match rx.recv_timeout(Duration::from_millis(50)) {
            Ok(Some(a)) => addr = Some(a),
            Ok(None) => ready = true,
            Err(_) => {}
        }
        if let Ok(Some(st)) = child.try_wait() {
            panic!("ringscan exited early ({st}): {}", stderr.lock().unwrap());
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "no live view after 30 s: {}",
            stderr.lock().unwrap()
        );
    }
    Served {
        child,
        addr: addr.unwrap(),
        stderr,
    }
}

impl Served {
    /// Waits for the exit (after `signal`, if given): (exit code, JSON summary, stderr).
    fn finish(mut self, signal: Option<&str>) -> (Option<i32>, Value, String) {
        if let Some(s) = signal {
            let st = Command::new("kill")
                .arg(format!("-{s}"))
                .arg(self.child.id().to_string())
                .status()
                .unwrap();
            assert!(st.success());
        }
        let mut out = String::new();
        if let Some(mut o) = self.child.stdout.take() {
            use std::io::Read;
            let _ = o.read_to_string(&mut out);
        }
        let status = self.child.wait().unwrap();
        std::thread::sleep(Duration::from_millis(50));
        let err = self.stderr.lock().unwrap().clone();
        let json = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out:?}\n{err}"));
        (status.code(), json, err)
    }
}

/// A blocking Foxglove WebSocket client.
struct Client {
    ws: WebSocket<TcpStream>,
    /// Advertised channels: id → (topic, encoding, schemaName, schema).
    channels: Vec<(u64, String, String, String, String)>,
    server_name: Option<String>,
}

/// One `messageData` frame.
#[derive(Debug, Clone)]
struct Data {
    subscription: u32,
    log_time_ns: u64,
    payload: Vec<u8>,
}

impl Client {
    fn connect(addr: SocketAddr) -> Client {
        let stream = TcpStream::connect(addr).expect("connect");
        stream
            .set_read_timeout(Some(Duration::from_secs(20)))
            .unwrap();
        let mut req = format!("ws://{addr}/").into_client_request().unwrap();
        req.headers_mut()
            .insert("sec-websocket-protocol", SUBPROTOCOL.parse().unwrap());
        let config = WebSocketConfig::default().max_message_size(Some(256 << 20));
        let (ws, resp) = tungstenite::client::client_with_config(req, stream, Some(config))
            .unwrap_or_else(|e| panic!("handshake: {e}"));
        assert_eq!(
            resp.headers()
                .get("sec-websocket-protocol")
                .and_then(|v| v.to_str().ok()),
            Some(SUBPROTOCOL),
            "the server selects the subprotocol"
        );
        Client {
            ws,
            channels: Vec::new(),
            server_name: None,
        }
    }

    fn on_text(&mut self, text: &str) {
        let v: Value = serde_json::from_str(text).expect("server text is JSON");
        match v["op"].as_str() {
            Some("serverInfo") => self.server_name = v["name"].as_str().map(str::to_string),
            Some("advertise") => {
                for c in v["channels"].as_array().expect("channels") {
                    let s = |k: &str| c[k].as_str().expect(k).to_string();
                    self.channels.push((
                        c["id"].as_u64().expect("id"),
                        s("topic"),
                        s("encoding"),
                        s("schemaName"),
                        s("schema"),
                    ));
                }
            }
            op => panic!("unexpected op {op:?}: {text}"),
        }
    }

    /// Reads until a channel on `topic` is advertised; returns its id.
    fn wait_channel(&mut self, topic: &str) -> u64 {
        loop {
            if let Some(c) = self.channels.iter().find(|c| c.1 == topic) {
                return c.0;
            }
            match self.ws.read().expect("read") {
                Message::Text(t) => self.on_text(t.as_str()),
                m => panic!("before subscribing: {m:?}"),
            }
        }
    }

    fn subscribe(&mut self, sub: u32, channel: u64) {
        let msg = serde_json::json!({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": channel}]});
        self.ws.send(Message::text(msg.to_string())).unwrap();
    }

    /// Every `messageData` frame until the server closes the connection.
    fn receive_all(&mut self) -> Vec<Data> {
        let mut out = Vec::new();
        loop {
            match self.ws.read() {
                Ok(Message::Text(t)) => self.on_text(t.as_str()),
                Ok(Message::Binary(b)) => {
                    assert!(b.len() >= 13, "short binary frame");
                    assert_eq!(b[0], 0x01, "opcode messageData");
                    out.push(Data {
                        subscription: u32::from_le_bytes(b[1..5].try_into().unwrap()),
                        log_time_ns: u64::from_le_bytes(b[5..13].try_into().unwrap()),
                        payload: b[13..].to_vec(),
                    });
                }
                Ok(Message::Close(_)) => {}
                Ok(_) => {}
                Err(tungstenite::Error::ConnectionClosed)
                | Err(tungstenite::Error::AlreadyClosed) => break,
                Err(tungstenite::Error::Io(e)) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    panic!("no message for 20 s")
                }
                Err(e) => panic!("read: {e}"),
            }
        }
        out
    }
}

fn varint(b: &[u8], at: &mut usize) -> u64 {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = b[*at];
        *at += 1;
        v |= u64::from(byte & 0x7f) << shift;
        if byte & 0x80 == 0 {
            return v;
        }
    }
    panic!("varint too long")
}

/// The fields of a `foxglove.PointCloud` (PointCloud.proto: timestamp = 1, frame_id = 2,
/// pose = 3, point_stride = 4 (fixed32), fields = 5, data = 6) this test looks at.
#[derive(Debug, Default)]
struct Cloud {
    timestamp_ns: u64,
    frame_id: String,
    point_stride: u32,
    field_names: Vec<String>,
    data_len: usize,
}

fn parse_cloud(msg: &[u8]) -> Cloud {
    let mut c = Cloud::default();
    let mut at = 0;
    while at < msg.len() {
        let key = varint(msg, &mut at);
        let (field, wire) = (key >> 3, key & 7);
        match wire {
            0 => {
                varint(msg, &mut at);
            }
            1 => at += 8,
            5 => {
                if field == 4 {
                    c.point_stride = u32::from_le_bytes(msg[at..at + 4].try_into().unwrap());
                }
                at += 4;
            }
            2 => {
                let len = varint(msg, &mut at) as usize;
                let body = &msg[at..at + len];
                match field {
                    1 => {
                        // google.protobuf.Timestamp { seconds = 1; nanos = 2; }
                        let (mut k, mut s, mut n) = (0, 0, 0);
                        while k < body.len() {
                            let key = varint(body, &mut k);
                            let v = varint(body, &mut k);
                            match key >> 3 {
                                1 => s = v,
                                2 => n = v,
                                _ => {}
                            }
                        }
                        c.timestamp_ns = s * 1_000_000_000 + n;
                    }
                    2 => c.frame_id = String::from_utf8(body.to_vec()).unwrap(),
                    5 => {
                        // PackedElementField { name = 1; … }
                        let mut k = 0;
                        while k < body.len() {
                            let key = varint(body, &mut k);
                            match key & 7 {
                                0 => {
                                    varint(body, &mut k);
                                }
                                5 => k += 4,
                                2 => {
                                    let l = varint(body, &mut k) as usize;
                                    if key >> 3 == 1 {
                                        c.field_names.push(
                                            String::from_utf8(body[k..k + l].to_vec()).unwrap(),
                                        );
                                    }
                                    k += l;
                                }
                                w => panic!("wire type {w} in a field"),
                            }
                        }
                    }
                    6 => c.data_len = len,
                    _ => {}
                }
                at += len;
            }
            w => panic!("wire type {w}"),
        }
    }
    c
}

/// (log time, payload) of every message on `topic` of an MCAP file, in file order.
fn mcap_messages(path: &Path, topic: &str) -> Vec<(u64, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == topic)
        .map(|m| (m.log_time, m.data.to_vec()))
        .collect()
}

/// The received frames are a run of consecutive messages of the file that ends with its last
/// one (nothing dropped after the subscription, the queue drained at the end), byte for byte
/// and with the same log times. Returns where the run starts.
fn assert_tail_of(received: &[Data], file: &[(u64, Vec<u8>)], what: &str) -> usize {
    assert!(
        received.len() <= file.len(),
        "{what}: {} received, {} in the file",
        received.len(),
        file.len()
    );
    let start = file.len() - received.len();
    for (i, d) in received.iter().enumerate() {
        let (t, payload) = &file[start + i];
        assert_eq!(d.log_time_ns, *t, "{what}: log time of sweep {}", start + i);
        assert!(
            d.payload == *payload,
            "{what}: payload of sweep {} differs from the MCAP message",
            start + i
        );
    }
    start
}

/// Checks the advertised `/points` channel: protobuf, foxglove.PointCloud, a base64 schema.
fn check_points_channel(c: &Client) {
    let ch = c.channels.iter().find(|c| c.1 == "/points").unwrap();
    assert_eq!(ch.2, "protobuf");
    assert_eq!(ch.3, "foxglove.PointCloud");
    assert!(
        !ch.4.is_empty()
            && ch.4.len() % 4 == 0
            && ch
                .4
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"+/=".contains(&b)),
        "schema is base64"
    );
    assert_eq!(c.server_name.as_deref(), Some("ringscan"));
}

#[test]
fn decode_serve_publishes_the_sweeps_of_the_mcap() {
    let _g = serial();
    let tmp = tmp_dir("decode");
    let out = tmp.join("run.mcap");
    let served = start(&[
        "decode".into(),
        demo_pcap().display().to_string(),
        "--out".into(),
        out.display().to_string(),
        "--serve".into(),
        "127.0.0.1:0".into(),
        "--serve-rate".into(),
        "1".into(),
        "--json".into(),
    ]);
    let mut client = Client::connect(served.addr);
    let channel = client.wait_channel("/points");
    client.subscribe(7, channel);
    let received = client.receive_all();
    let (code, json, err) = served.finish(None);
    assert_eq!(code, Some(0), "{err}");
    check_points_channel(&client);

    let file = mcap_messages(&out, "/points");
    assert_eq!(file.len() as u64, json["sweeps"].as_u64().unwrap());
    assert!(
        received.len() >= 2,
        "{} sweeps received of {}\n{err}",
        received.len(),
        file.len()
    );
    let start = assert_tail_of(&received, &file, "decode --serve");
    let name = json["sensors"][0]["name"].as_str().unwrap();
    let mut points = 0u64;
    for d in &received {
        assert_eq!(d.subscription, 7);
        let c = parse_cloud(&d.payload);
        assert_eq!(
            c.frame_id, name,
            "frame_id = the sensor name of decode --json"
        );
        assert_eq!(c.point_stride, 24);
        assert_eq!(
            c.field_names,
            ["x", "y", "z", "intensity", "t", "ring", "return"]
        );
        assert_eq!(c.data_len % 24, 0);
        assert!(c.timestamp_ns > 0);
        points += (c.data_len / 24) as u64;
    }
    // Every point of the sweeps not received plus those received = decode --json's total.
    let missed: u64 = file[..start]
        .iter()
        .map(|(_, p)| (parse_cloud(p).data_len / 24) as u64)
        .sum();
    assert_eq!(missed + points, json["points"].as_u64().unwrap());
    eprintln!(
        "decode --serve: {} of {} sweeps received (from sweep {start}), {points} points; serve {}",
        received.len(),
        file.len(),
        json["serve"]
    );
    let s = &json["serve"];
    assert_eq!(s["clients_total"], 1);
    assert_eq!(s["messages_dropped"], 0);
    assert_eq!(s["messages_sent"], received.len() as u64);
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn serve_refuses_a_client_without_the_subprotocol() {
    let _g = serial();
    let served = start(&[
        "decode".into(),
        demo_pcap().display().to_string(),
        "--serve".into(),
        "127.0.0.1:0".into(),
        "--json".into(),
    ]);
    let stream = TcpStream::connect(served.addr).unwrap();
    let r = tungstenite::client::client(format!("ws://{}/", served.addr), stream);
    match r {
        Err(tungstenite::HandshakeError::Failure(tungstenite::Error::Http(resp))) => {
            assert_eq!(resp.status(), 400)
        }
        Err(e) => panic!("expected HTTP 400, got {e}"),
        Ok(_) => panic!("a client without {SUBPROTOCOL} was accepted"),
    }
    let (code, json, err) = served.finish(None);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(json["serve"]["handshakes_failed"], 1);
    assert_eq!(json["serve"]["clients_total"], 0);
}

/// `listen --serve` fed by `replay`: a client that reads gets every sweep after its subscription
/// while a client that never reads only loses its own messages (counted), and the receive path
/// loses nothing.
#[test]
fn listen_serve_slow_client_does_not_slow_the_others() {
    let _g = serial();
    let tmp = tmp_dir("listen");
    let out = tmp.join("live.mcap");
    let pcap = demo_pcap();
    let offset = free_offset(&[2368, 8308]);
    let served = start(&[
        "listen".into(),
        "--sensor".into(),
        format!("127.0.0.1:{}", 2368 + offset),
        "--out".into(),
        out.display().to_string(),
        "--serve".into(),
        "127.0.0.1:0".into(),
        "--serve-queue".into(),
        "4".into(),
        "--json".into(),
    ]);
    let addr = served.addr;
    // The slow client: subscribes, then never reads again.
    let mut slow = Client::connect(addr);
    // The reading client, on its own thread.
    let (tx, rx) = mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut c = Client::connect(addr);
        let ch = c.wait_channel("/points");
        c.subscribe(1, ch);
        tx.send(()).unwrap();
        let got = c.receive_all();
        (got, c)
    });
    // Packets first: the channel is advertised once the sensor is known.
    let replayer = std::thread::spawn(move || replay(&pcap, offset, "1", &["--loop", "3"]));
    let ch = slow.wait_channel("/points");
    slow.subscribe(3, ch);
    rx.recv_timeout(Duration::from_secs(30))
        .expect("reader subscribed");
    replayer.join().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let (code, json, err) = served.finish(Some("INT"));
    assert_eq!(code, Some(0), "{err}");
    let (received, reading) = reader.join().unwrap();
    check_points_channel(&reading);
    drop(slow);

    // The receive path lost nothing.
    assert_eq!(json["receive"]["queue_dropped"], 0, "{err}");
    assert_eq!(json["packets"]["missing"], 0, "{err}");
    let file = mcap_messages(&out, "/points");
    assert_eq!(file.len() as u64, json["sweeps"].as_u64().unwrap());
    assert!(
        received.len() >= 2,
        "{} sweeps of {}",
        received.len(),
        file.len()
    );
    // The reading client: every sweep since it subscribed, unchanged.
    assert_tail_of(&received, &file, "reading client");
    for d in &received {
        assert_eq!(d.subscription, 1);
        let c = parse_cloud(&d.payload);
        assert_eq!(c.frame_id, json["sensors"][0]["name"].as_str().unwrap());
    }
    // The slow client lost messages, and only it.
    let s = &json["serve"];
    eprintln!(
        "listen --serve: reading client {} of {} sweeps; serve {s}",
        received.len(),
        file.len()
    );
    assert_eq!(s["clients_total"], 2, "{s}");
    let clients = s["clients"].as_array().unwrap();
    let dropped: Vec<u64> = clients
        .iter()
        .map(|c| c["dropped"].as_u64().unwrap())
        .collect();
    assert!(
        dropped.iter().filter(|&&d| d == 0).count() == 1
            && dropped.iter().filter(|&&d| d > 0).count() == 1,
        "per-client drops {dropped:?}"
    );
    assert_eq!(
        s["messages_dropped"].as_u64().unwrap(),
        dropped.iter().sum::<u64>()
    );
    let _ = std::fs::remove_dir_all(&tmp);
}

/// `decode --pipeline default --serve`: the pipeline outputs are published with the payloads of
/// the MCAP's `/ground`, `/obstacles` and `/clusters`.
#[test]
fn decode_serve_publishes_the_pipeline_outputs() {
    let _g = serial();
    let tmp = tmp_dir("pipeline");
    let out = tmp.join("pipeline.mcap");
    let served = start(&[
        "decode".into(),
        demo_pcap().display().to_string(),
        "--out".into(),
        out.display().to_string(),
        "--pipeline".into(),
        "default".into(),
        "--serve".into(),
        "127.0.0.1:0".into(),
        "--json".into(),
    ]);
    let mut client = Client::connect(served.addr);
    let topics = ["/ground", "/obstacles", "/clusters"];
    for (k, t) in topics.iter().enumerate() {
        let ch = client.wait_channel(t);
        client.subscribe(100 + k as u32, ch);
    }
    let received = client.receive_all();
    let (code, json, err) = served.finish(None);
    assert_eq!(code, Some(0), "{err}");
    let schema = |t: &str| {
        let c = client.channels.iter().find(|c| c.1 == t).unwrap();
        (c.2.clone(), c.3.clone())
    };
    assert_eq!(
        schema("/ground"),
        ("protobuf".into(), "foxglove.PointCloud".into())
    );
    assert_eq!(
        schema("/obstacles"),
        ("protobuf".into(), "foxglove.PointCloud".into())
    );
    assert_eq!(
        schema("/clusters"),
        ("protobuf".into(), "foxglove.SceneUpdate".into())
    );
    for (k, t) in topics.iter().enumerate() {
        let got: Vec<Data> = received
            .iter()
            .filter(|d| d.subscription == 100 + k as u32)
            .cloned()
            .collect();
        let file = mcap_messages(&out, t);
        assert_eq!(file.len() as u64, json["sweeps"].as_u64().unwrap(), "{t}");
        assert!(
            got.len() >= 2,
            "{t}: {} of {} received",
            got.len(),
            file.len()
        );
        assert_tail_of(&got, &file, t);
        if *t == "/obstacles" {
            let c = parse_cloud(&got[0].payload);
            assert_eq!(c.point_stride, 28);
            assert_eq!(c.field_names.last().map(String::as_str), Some("cluster"));
        }
    }
    assert_eq!(json["serve"]["messages_dropped"], 0);
    let _ = std::fs::remove_dir_all(&tmp);
}

/// The protocol details, in process: `serverInfo`, `advertise` (also of later channels), invalid
/// subscriptions ignored, `messageData` layout, `unsubscribe`, the connection limit, and that
/// every publish is either queued or counted as dropped for a client that never reads.
#[test]
fn live_view_protocol_in_process() {
    use ringscan::sink::live_view::{ChannelSpec, LiveView, ServeOptions};
    use std::sync::atomic::Ordering;

    let view = LiveView::bind(
        "127.0.0.1:0".parse().unwrap(),
        ServeOptions {
            queue_messages: 2,
            max_clients: 2,
            ..ServeOptions::default()
        },
    )
    .unwrap();
    let spec = |topic| ChannelSpec {
        topic,
        encoding: "protobuf",
        schema_name: "test.Msg",
        schema: b"foobar",
    };
    let a = view.add_channel(&spec("/a"));
    let b = view.add_channel(&spec("/b"));
    let wait = |what: &str, f: &dyn Fn() -> bool| {
        let t = Instant::now();
        while !f() {
            assert!(t.elapsed() < Duration::from_secs(10), "{what}");
            std::thread::sleep(Duration::from_millis(5));
        }
    };

    let mut c1 = Client::connect(view.local_addr());
    assert_eq!(c1.wait_channel("/b"), u64::from(b.0));
    assert_eq!(c1.server_name.as_deref(), Some("ringscan"));
    let ch_a = c1.channels.iter().find(|c| c.1 == "/a").unwrap().clone();
    // RFC 4648 test vector: "foobar" → "Zm9vYmFy".
    assert_eq!(
        (ch_a.0, ch_a.2.as_str(), ch_a.3.as_str(), ch_a.4.as_str()),
        (u64::from(a.0), "protobuf", "test.Msg", "Zm9vYmFy")
    );
    // One valid subscription, one to an unknown channel, one reusing the id.
    let msg = serde_json::json!({"op": "subscribe", "subscriptions": [
        {"id": 5, "channelId": a.0}, {"id": 6, "channelId": 99}, {"id": 5, "channelId": b.0}]});
    c1.ws.send(Message::text(msg.to_string())).unwrap();
    wait("subscribed to /a", &|| view.has_subscribers(a));
    assert!(
        !view.has_subscribers(b),
        "a reused subscription id is ignored"
    );
    assert_eq!(view.publish(b, 1, b"nobody"), 0);
    assert_eq!(view.publish(a, 0x0102_0304_0506_0708, b"hello"), 1);
    match c1.ws.read().unwrap() {
        Message::Binary(f) => assert_eq!(
            &f[..],
            [1, 5, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1, b'h', b'e', b'l', b'l', b'o']
        ),
        m => panic!("expected messageData, got {m:?}"),
    }
    // A channel added later is advertised to the connected client.
    let c = view.add_channel(&spec("/c"));
    assert_eq!(c1.wait_channel("/c"), u64::from(c.0));
    let unsub = serde_json::json!({"op": "unsubscribe", "subscriptionIds": [5]});
    c1.ws.send(Message::text(unsub.to_string())).unwrap();
    wait("unsubscribed", &|| !view.has_subscribers(a));

    // A second client that subscribes and never reads; a third is over the limit.
    let mut c2 = Client::connect(view.local_addr());
    c2.wait_channel("/a");
    c2.subscribe(1, u64::from(a.0));
    wait("second client subscribed", &|| view.has_subscribers(a));
    let refused = TcpStream::connect(view.local_addr()).and_then(|s| {
        tungstenite::client::client(format!("ws://{}/", view.local_addr()), s)
            .map(|_| ())
            .map_err(|e| std::io::Error::other(e.to_string()))
    });
    assert!(refused.is_err(), "a third connection is refused");
    let stats = view.stats();
    wait("refusal counted", &|| {
        stats.clients_refused.load(Ordering::Relaxed) == 1
    });
    let payload = vec![7u8; 256 << 10];
    let mut queued = 0;
    for i in 0..200 {
        queued += view.publish(a, i, &payload);
    }
    let dropped = stats.messages_dropped.load(Ordering::Relaxed);
    assert!(dropped > 0, "a client that never reads loses messages");
    assert_eq!(
        queued as u64 + dropped,
        200,
        "every message queued or counted"
    );
    let clients = view.close(Duration::from_millis(200));
    assert_eq!(clients.len(), 2);
    assert_eq!(clients.iter().map(|c| c.dropped).sum::<u64>(), dropped);
    eprintln!("in process: 200 publishes of 256 KiB to a client that never reads: {queued} queued, {dropped} dropped");
}
