//! `--serve ADDR`: the live view of `decode` and `listen` ([`crate::sink::live_view`]).
//!
//! Per sensor the same topics and payloads as the MCAP file: `<prefix>/points`
//! (`foxglove.PointCloud`, the bytes the MCAP sink writes with `--format foxglove`, also when the
//! file is written as ROS 2) and, with `--pipeline`, `<prefix>/ground`, `<prefix>/obstacles` and
//! `<prefix>/clusters`. A message is encoded only when a client subscribes to its topic.
//!
//! `decode --serve` paces its sweeps by their capture times (`--serve-rate`, real time by
//! default; `max` publishes as fast as it decodes), so a capture plays into the Foxglove app as it
//! was recorded. `listen` never waits: sweeps are published as they are assembled.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use crate::pipeline::cluster::Cluster;
use crate::point::{interleave_extended, Point, EXTENDED_FIELDS, EXTENDED_STRIDE};
use crate::sink::foxglove::{self, PointCloudPrefix};
use crate::sink::live_view::{
    ChannelId, ChannelSpec, LiveView, LiveViewStats, ServeOptions, DEFAULT_QUEUE_MESSAGES,
};
use crate::sink::scene::{self, SceneEncoder, OBSTACLE_FIELDS, OBSTACLE_STRIDE};
use crate::source::udp::Rate;
use crate::sweep::Sweep;
use serde_json::{json, Value};

use super::run::RunError;

/// How long `close` lets clients' queues drain at the end of a run.
const DRAIN: Duration = Duration::from_secs(2);
/// Largest wait of `decode --serve` between two messages: a longer gap in the capture's clock
/// is skipped.
const MAX_PACE_GAP: Duration = Duration::from_secs(5);

/// The `--serve` flags `decode` and `listen` share.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ServeArgs {
    /// Serve a live view on ADDR (e.g. 127.0.0.1:8765; port 0 = any free port) over the Foxglove
    /// WebSocket protocol: open ws://ADDR in the Foxglove app.
    #[arg(long, value_name = "ADDR")]
    pub serve: Option<SocketAddr>,
    /// Messages queued per live view client; a client slower than the sensor misses the
    /// messages that do not fit (counted in `serve.messages_dropped`).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_QUEUE_MESSAGES, requires = "serve")]
    pub serve_queue: usize,
}

/// The publisher as the session and the pipeline share it (one thread).
pub type SharedPublisher = std::rc::Rc<std::cell::RefCell<LivePublisher>>;

/// One sensor's live channels.
struct SensorLive {
    name: String,
    prefix: String,
    points: ChannelId,
    points_prefix: PointCloudPrefix,
    extended_prefix: Option<PointCloudPrefix>,
    pipeline: Option<PipelineLive>,
}

/// One sensor's pipeline channels.
struct PipelineLive {
    ground: ChannelId,
    obstacles: ChannelId,
    clusters: ChannelId,
    ground_prefix: PointCloudPrefix,
    obstacles_prefix: PointCloudPrefix,
}

/// Pacing of `decode --serve`: capture time → wall time.
struct Pace {
    factor: f64,
    origin: Option<(Instant, u64)>,
}

/// Publishes a run's sweeps and pipeline outputs to the live view.
pub struct LivePublisher {
    view: Option<LiveView>,
    stats: std::sync::Arc<LiveViewStats>,
    addr: SocketAddr,
    sensors: Vec<Option<SensorLive>>,
    pace: Option<Pace>,
    buf: Vec<u8>,
    records: Vec<u8>,
    scene: SceneEncoder,
    /// Final JSON once closed.
    closed: Option<Value>,
    /// Messages not published because they exceed the protobuf size limit.
    too_large: u64,
    /// `/tf` (`--odometry`), made on the first pose.
    tf: Option<ChannelId>,
}

impl std::fmt::Debug for LivePublisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LivePublisher")
            .field("addr", &self.addr)
            .finish_non_exhaustive()
    }
}

impl LivePublisher {
    /// Starts the server of `--serve` (`None` without it). `rate` paces publishing by capture
    /// time (`decode`); `None` never waits (`listen`).
    pub fn start(args: &ServeArgs, rate: Option<Rate>) -> Result<Option<Self>, RunError> {
        let Some(addr) = args.serve else {
            return Ok(None);
        };
        if args.serve_queue == 0 {
            return Err(RunError::Usage(
                "--serve-queue: expected at least 1 message".into(),
            ));
        }
        let view = LiveView::bind(
            addr,
            ServeOptions {
                queue_messages: args.serve_queue,
                ..ServeOptions::default()
            },
        )
        .map_err(|e| RunError::Live(e.to_string()))?;
        let addr = view.local_addr();
        tracing::info!("live view: serving the Foxglove WebSocket protocol on ws://{addr}");
        Ok(Some(Self {
            stats: view.stats(),
            view: Some(view),
            addr,
            sensors: Vec::new(),
            pace: match rate {
                Some(Rate::Factor(f)) => Some(Pace {
                    factor: f,
                    origin: None,
                }),
                Some(Rate::Max) | None => None,
            },
            buf: Vec::new(),
            records: Vec::new(),
            scene: SceneEncoder::default(),
            closed: None,
            too_large: 0,
            tf: None,
        }))
    }

    /// The counters, for a status line on another thread.
    pub fn stats(&self) -> std::sync::Arc<LiveViewStats> {
        self.stats.clone()
    }

    /// Makes the channels of sensor `idx`, named `name` (its frame id), whose topics start with
    /// `prefix` (`""` for a single sensor, else `/<name>`).
    pub fn add_sensor(&mut self, idx: usize, name: &str, prefix: &str) {
        let Some(view) = self.view.as_ref() else {
            return;
        };
        while self.sensors.len() <= idx {
            self.sensors.push(None);
        }
        if self.sensors[idx].is_some() {
            return;
        }
        let schema = foxglove::point_cloud_descriptor_set();
        let points = view.add_channel(&ChannelSpec {
            topic: &format!("{prefix}/points"),
            encoding: "protobuf",
            schema_name: foxglove::POINT_CLOUD_SCHEMA,
            schema: &schema,
        });
        self.sensors[idx] = Some(SensorLive {
            name: name.to_string(),
            prefix: prefix.to_string(),
            points,
            points_prefix: PointCloudPrefix::new(name),
            extended_prefix: None,
            pipeline: None,
        });
    }

    fn pace(&mut self, log_time_ns: u64) {
        let Some(p) = self.pace.as_mut() else {
            return;
        };
        let now = Instant::now();
        let (wall0, log0) = *p.origin.get_or_insert((now, log_time_ns));
        let since_s = (log_time_ns as f64 - log0 as f64) * 1e-9 / p.factor;
        let due_s = since_s - now.duration_since(wall0).as_secs_f64();
        // A capture's clock that jumps back or more than MAX_PACE_GAP ahead starts the pacing
        // afresh instead of rushing or stalling.
        if since_s < 0.0 || due_s > MAX_PACE_GAP.as_secs_f64() {
            p.origin = Some((now, log_time_ns));
        } else if due_s > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(due_s));
        }
    }

    /// Publishes one sweep of sensor `idx` on its `points` topic.
    pub fn sweep(&mut self, idx: usize, sweep: &Sweep) {
        let log_time = sweep.last_host_ns.max(0) as u64;
        let stamp = sweep.timestamp_ns.max(0) as u64;
        self.pace(log_time);
        let (Some(view), Some(Some(s))) = (self.view.as_ref(), self.sensors.get_mut(idx)) else {
            return;
        };
        if !view.has_subscribers(s.points) {
            return;
        }
        let encoded = if sweep.extras.len() == sweep.points.len() && !sweep.extras.is_empty() {
            interleave_extended(&sweep.points, &sweep.extras, &mut self.records);
            let prefix = s.extended_prefix.get_or_insert_with(|| {
                PointCloudPrefix::with_fields(&s.name, EXTENDED_STRIDE, &EXTENDED_FIELDS)
            });
            foxglove::encode_point_cloud_bytes(&mut self.buf, stamp, prefix, &self.records)
        } else {
            foxglove::encode_point_cloud(&mut self.buf, stamp, &s.points_prefix, &sweep.points)
        };
        match encoded {
            Some(()) => {
                view.publish(s.points, log_time, &self.buf);
            }
            None => self.too_large += 1,
        }
    }

    /// Publishes one encoded `foxglove.FrameTransform` on `/tf` (`--odometry`).
    pub fn tf(&mut self, log_time_ns: u64, frame_transform: &[u8]) {
        let Some(view) = self.view.as_ref() else {
            return;
        };
        let tf = *self.tf.get_or_insert_with(|| {
            view.add_channel(&ChannelSpec {
                topic: "/tf",
                encoding: "protobuf",
                schema_name: scene::FRAME_TRANSFORM_SCHEMA,
                schema: &scene::frame_transform_descriptor_set(),
            })
        });
        if view.has_subscribers(tf) {
            view.publish(tf, log_time_ns, frame_transform);
        }
    }

    /// Publishes one sweep's pipeline outputs of sensor `idx` (points in `frame_id`).
    #[allow(clippy::too_many_arguments)]
    pub fn pipeline(
        &mut self,
        idx: usize,
        frame_id: &str,
        log_time_ns: u64,
        timestamp_ns: u64,
        ground: &[Point],
        obstacles: &[Point],
        obstacle_clusters: &[u32],
        clusters: &[Cluster],
    ) {
        self.pace(log_time_ns);
        let (Some(view), Some(Some(s))) = (self.view.as_ref(), self.sensors.get_mut(idx)) else {
            return;
        };
        let p = s.pipeline.get_or_insert_with(|| {
            let points = foxglove::point_cloud_descriptor_set();
            let cloud = |name: &str| {
                view.add_channel(&ChannelSpec {
                    topic: &format!("{}/{name}", s.prefix),
                    encoding: "protobuf",
                    schema_name: foxglove::POINT_CLOUD_SCHEMA,
                    schema: &points,
                })
            };
            let ground = cloud("ground");
            let obstacles = cloud("obstacles");
            let scene_schema = scene::scene_update_descriptor_set();
            let clusters = view.add_channel(&ChannelSpec {
                topic: &format!("{}/clusters", s.prefix),
                encoding: "protobuf",
                schema_name: scene::SCENE_UPDATE_SCHEMA,
                schema: &scene_schema,
            });
            PipelineLive {
                ground,
                obstacles,
                clusters,
                ground_prefix: PointCloudPrefix::new(frame_id),
                obstacles_prefix: PointCloudPrefix::with_fields(
                    frame_id,
                    OBSTACLE_STRIDE,
                    &OBSTACLE_FIELDS,
                ),
            }
        });
        if view.has_subscribers(p.ground) {
            match foxglove::encode_point_cloud(
                &mut self.buf,
                timestamp_ns,
                &p.ground_prefix,
                ground,
            ) {
                Some(()) => {
                    view.publish(p.ground, log_time_ns, &self.buf);
                }
                None => self.too_large += 1,
            }
        }
        if view.has_subscribers(p.obstacles) {
            scene::obstacle_records(obstacles, obstacle_clusters, &mut self.records);
            match foxglove::encode_point_cloud_bytes(
                &mut self.buf,
                timestamp_ns,
                &p.obstacles_prefix,
                &self.records,
            ) {
                Some(()) => {
                    view.publish(p.obstacles, log_time_ns, &self.buf);
                }
                None => self.too_large += 1,
            }
        }
        if view.has_subscribers(p.clusters) {
            self.scene
                .encode_clusters(&mut self.buf, timestamp_ns, frame_id, clusters);
            view.publish(p.clusters, log_time_ns, &self.buf);
        }
    }

    /// Lets the clients' queues drain (up to 2 s), closes the server and keeps the final
    /// counters for [`LivePublisher::summary`].
    pub fn close(&mut self) {
        if let Some(view) = self.view.take() {
            let clients = view
                .close(DRAIN)
                .into_iter()
                .map(|c| {
                    json!({
                        "peer": c.peer.map(|p| p.to_string()),
                        "sent": c.sent,
                        "dropped": c.dropped,
                        "connected_at_close": c.connected,
                    })
                })
                .collect();
            self.closed = Some(self.summary_now(Some(clients)));
        }
    }

    fn summary_now(&self, clients: Option<Vec<Value>>) -> Value {
        let s = &self.stats;
        let g = |a: &std::sync::atomic::AtomicU64| a.load(std::sync::atomic::Ordering::Relaxed);
        let mut v = json!({
            "address": self.addr.to_string(),
            "clients_total": g(&s.clients_total),
            "handshakes_failed": g(&s.handshakes_failed),
            "clients_refused": g(&s.clients_refused),
            "messages_queued": g(&s.messages_queued),
            "messages_sent": g(&s.messages_sent),
            "messages_dropped": g(&s.messages_dropped),
            "messages_too_large": self.too_large,
            "bytes_sent": g(&s.bytes_sent),
        });
        if let (Some(c), Some(o)) = (clients, v.as_object_mut()) {
            o.insert("clients".into(), Value::Array(c));
        }
        v
    }

    /// The `serve` object of the `--json` summary.
    pub fn summary(&self) -> Value {
        match &self.closed {
            Some(v) => v.clone(),
            None => self.summary_now(None),
        }
    }
}

/// The live view part of the status line of `listen`.
pub fn status(stats: &LiveViewStats) -> String {
    let g = |a: &std::sync::atomic::AtomicU64| a.load(std::sync::atomic::Ordering::Relaxed);
    format!(
        " · live view: {} clients, dropped {}",
        g(&stats.clients_connected),
        g(&stats.messages_dropped)
    )
}
