//! Command-line front end: clap commands, progress, exit codes. No algorithms live here.

/// `println!` for a command's output on stdout, without its panic when stdout cannot be written
/// (a reader gone, `ringscan info X | head -1`; a full device): the failure is kept for
/// [`run`]'s exit code ([`write_stdout`]).
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!($($arg)*))
    };
}

pub mod bag_args;
pub mod listen;
pub mod livox_ctl;
pub mod odometry;
pub mod pipeline;
pub mod ptc;
pub mod render;
pub mod replay;
pub mod report;
pub mod run;
pub mod sensors;
pub mod serve;
pub mod session;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};

pub use run::{DecodeArgs, RunError};

/// ringscan: LiDAR packets to trustworthy point clouds.
#[derive(Parser, Debug)]
#[command(name = "ringscan", version, about, long_about = None)]
struct Cli {
    /// More log output on stderr (-v info, -vv debug). RINGSCAN_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Decode a capture (pcap, pcapng, ROS bag, Livox .lvx / .lvx2) into sweeps, written to MCAP.
    Decode(DecodeCmd),
    /// Tell what a capture holds: sensors, models, return modes, ports, duration, sweeps, loss.
    Info(InfoCmd),
    /// Decode the built-in example capture (a simulated VLP-16) and write demo.mcap.
    Demo(DemoCmd),
    /// Receive sensors' UDP packets live, decode them and write MCAP until SIGINT / SIGTERM / SIGHUP.
    Listen(ListenCmd),
    /// Send a capture's UDP payloads again, paced by its timestamps.
    Replay(ReplayCmd),
    /// Draw a bird's-eye picture of one sweep of an MCAP written with `--pipeline`.
    Render(render::RenderCmd),
    /// Fetch a Hesai sensor's angle-correction file over its TCP control port (PTC, 9347), for
    /// `--calib`.
    HesaiCalib(HesaiCalibCmd),
}

#[derive(clap::Args, Debug)]
struct HesaiCalibCmd {
    /// The sensor's address, optionally with its PTC port (default 9347).
    #[arg(long, value_name = "IP[:PORT]")]
    sensor: String,
    /// Where to write the file (the CSV, or the AT128's or ATX's .dat).
    #[arg(long, short)]
    out: PathBuf,
    /// Also fetch the Pandar ATX's firetime correction (PTC 0xA9) and write it here as the CSV
    /// that `--calib` joins to the `.dat`.
    #[arg(long, value_name = "CSV")]
    firetimes: Option<PathBuf>,
    /// Seconds the sensor has to answer in full (connecting, and each command's whole reply).
    #[arg(long, default_value_t = 5.0)]
    timeout: f64,
}

fn hesai_calib_command(c: &HesaiCalibCmd) -> Result<ExitCode, RunError> {
    let addr: std::net::SocketAddr = match c.sensor.parse() {
        Ok(a) => a,
        Err(_) => match c.sensor.parse::<std::net::IpAddr>() {
            Ok(ip) => std::net::SocketAddr::new(ip, ptc::PTC_PORT),
            Err(_) => {
                return Err(RunError::Usage(format!(
                    "--sensor {}: expected IP or IP:PORT",
                    c.sensor
                )))
            }
        },
    };
    let timeout = seconds("--timeout", c.timeout).map_err(RunError::Usage)?;
    let bytes = ptc::fetch_angle_correction(addr, timeout).map_err(RunError::Live)?;
    std::fs::write(&c.out, &bytes)
        .map_err(|e| RunError::Live(format!("{}: {e}", c.out.display())))?;
    outln!(
        "{}: {} bytes of angle correction from {addr}",
        c.out.display(),
        bytes.len()
    );
    if let Some(path) = &c.firetimes {
        let f = ptc::fetch_atx_firetimes(addr, timeout).map_err(RunError::Live)?;
        std::fs::write(path, f.to_csv())
            .map_err(|e| RunError::Live(format!("{}: {e}", path.display())))?;
        outln!(
            "{}: firetime correction of {} channels from {addr}",
            path.display(),
            f.channels()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Point cloud message layout.
#[derive(Clone, Copy, Debug, Default, ValueEnum, PartialEq, Eq)]
pub enum FormatArg {
    /// foxglove.PointCloud (protobuf).
    #[default]
    Foxglove,
    /// sensor_msgs/msg/PointCloud2 (CDR).
    Ros2,
}

/// Packet CRC checking (Ouster, Hesai, Livox).
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum CrcArg {
    /// Check where the sensor writes valid CRCs (Ouster: firmware ≥ 2.5, not FUSA).
    Auto,
    /// Always check (packets with a bad CRC are dropped and counted).
    On,
    /// Never check.
    Off,
}

/// Which point fields are written.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum FieldsArg {
    /// x, y, z, intensity, t, ring, return (24-byte records).
    Default,
    /// x, y, z, intensity only (16-byte records).
    Minimal,
    /// The default fields plus every extra field the sensor has (none for Velodyne).
    All,
}

/// How datagrams become sweeps and messages: the options `decode` and `listen` share.
#[derive(clap::Args, Debug)]
struct SweepOpts {
    /// Sensor name (frame id and topic prefix); only with a single sensor.
    #[arg(long, value_parser = parse_name)]
    name: Option<String>,
    /// Azimuth at which sweeps are cut, degrees.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.0)]
    cut_angle: f64,
    /// Drop points closer than this, metres.
    #[arg(long, allow_negative_numbers = true)]
    min_range: Option<f32>,
    /// Drop points farther than this, metres.
    #[arg(long, allow_negative_numbers = true)]
    max_range: Option<f32>,
    /// Hesai multi-return: also drop a return that is not its firing's last when within this
    /// many metres of another (nebula's dual_return_distance_threshold, e.g. 0.1); default:
    /// only identical returns are merged.
    #[arg(long, value_name = "M")]
    dual_return_threshold: Option<f32>,
    /// Hesai: keep only points whose corrected azimuth lies between START and END degrees
    /// (clockwise from forward), e.g. 30:150.
    #[arg(long, value_name = "START:END", value_parser = parse_fov)]
    fov: Option<(f64, f64)>,
    /// Sensors that do not spin (Livox): a sweep per integration period of this many ms
    /// (default 100).
    #[arg(long, value_name = "MS")]
    integration_ms: Option<f64>,
    /// Point fields written.
    #[arg(long, value_enum, default_value_t = FieldsArg::Default)]
    fields: FieldsArg,
    /// Message layout.
    #[arg(long, value_enum, default_value_t = FormatArg::Foxglove, requires = "out")]
    format: FormatArg,
    /// Also write every UDP payload to `/raw`, so the drive can be decoded again later.
    #[arg(long, requires = "out")]
    raw: bool,
    /// Packet CRC checks (Ouster footer CRC-64, Hesai CRC-32, Livox CRC-32): `auto` = where
    /// the sensor writes them (Ouster: firmware ≥ 2.5, not FUSA), `on`, `off`.
    #[arg(long, value_enum, default_value_t = CrcArg::Auto)]
    crc: CrcArg,
    #[command(flatten)]
    pipeline: pipeline::PipelineArgs,
    #[command(flatten)]
    odometry: odometry::OdometryArgs,
}

impl SweepOpts {
    /// The session's options, with the sensor selection each command reads its own way.
    fn session(
        self,
        model: Option<String>,
        calib: Vec<String>,
        port: Option<u16>,
    ) -> session::SessionOptions {
        session::SessionOptions {
            model,
            calib,
            name: self.name,
            port,
            cut_angle_deg: self.cut_angle,
            min_range: self.min_range,
            max_range: self.max_range,
            dual_return_threshold_m: self.dual_return_threshold,
            fov_deg: self.fov,
            integration_ms: self.integration_ms,
            fields_all: self.fields == FieldsArg::All,
            raw: self.raw,
            crc: match self.crc {
                CrcArg::Auto => None,
                CrcArg::On => Some(true),
                CrcArg::Off => Some(false),
            },
            pipeline: self.pipeline,
            format: self.format,
            odometry: self.odometry,
            keep_columns: false,
            inspect: false,
        }
    }
}

#[derive(clap::Args, Debug)]
struct DecodeCmd {
    /// Input capture (.pcap or .pcapng), ROS bag (ROS 1 .bag; rosbag2 directory, .db3 or
    /// .mcap) or Livox recording (.lvx, .lvx2), told apart by its bytes.
    input: PathBuf,
    /// Output MCAP file (omit to decode and count only).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Sensor model, overriding detection. Velodyne: vlp16, puck-hires, hdl32e, vlp32c,
    /// hdl64e-s2, hdl64e-s3, vls128; Hesai: pandar40p, pandar64, pandarqt64, pandarqt128,
    /// pandarxt16, pandarxt32, pandarxt32m, pandarat128, pandarot128, pandaratx; Robosense:
    /// rs16, rs32, rsbpearl, rshelios, rshelios16p, rsruby128, rsm1; Livox: mid360, hap, avia,
    /// horizon, tele15, mid40, mid70.
    #[arg(long)]
    model: Option<String>,
    /// Calibration file: Velodyne ROS yaml, VeloView xml or HDL-64E db.xml; Ouster metadata
    /// JSON; Hesai angle-correction CSV, AT128 or ATX .dat; Robosense angle CSV. `ADDR=FILE` gives
    /// it to the sensor at that source address only. Repeatable.
    #[arg(long = "calib", value_name = "[ADDR=]FILE")]
    calib: Vec<String>,
    /// Only data packets sent to this UDP port.
    #[arg(long)]
    port: Option<u16>,
    #[command(flatten)]
    sweeps: SweepOpts,
    /// MCAP chunk compression: `zstd` (level −3, a fast level), `zstd:LEVEL` (−7 … 19; negative levels are
    /// zstd's fast modes), `lz4` or `none`.
    #[arg(long, default_value = "zstd", requires = "out")]
    compression: session::ChunkCompression,
    /// Threads compressing MCAP chunks (default: the machine's cores); 1 = decode and compress
    /// on one thread.
    #[arg(long, value_name = "N", value_parser = parse_threads, requires = "out", allow_negative_numbers = true)]
    threads: Option<usize>,
    /// Uncompressed size of an MCAP chunk, MiB (fractions allowed).
    #[arg(long, value_name = "MIB", default_value = "4", value_parser = parse_chunk_size, requires = "out", allow_negative_numbers = true)]
    chunk_size: u64,
    /// Exit with an error if any packet was missing, dropped or malformed.
    #[arg(long)]
    strict: bool,
    /// Print one JSON summary object on stdout at the end.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    serve: serve::ServeArgs,
    #[command(flatten)]
    bag: bag_args::BagArgs,
    /// With --serve: publish sweeps at this speed of their capture times (`1.0` = as recorded,
    /// `2`, `0.5`, or `max` = as fast as they are decoded).
    #[arg(long, value_name = "FACTOR|max", default_value = "1.0", value_parser = replay::parse_rate, requires = "serve")]
    serve_rate: crate::source::udp::Rate,
}

#[derive(clap::Args, Debug)]
struct InfoCmd {
    /// Input capture (.pcap or .pcapng), ROS bag or Livox recording (.lvx, .lvx2), as for
    /// `decode`.
    input: PathBuf,
    /// Sensor model, overriding detection.
    #[arg(long)]
    model: Option<String>,
    /// Calibration file(s), as for `decode`.
    #[arg(long = "calib", value_name = "[ADDR=]FILE")]
    calib: Vec<String>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    bag: bag_args::BagArgs,
}

#[derive(clap::Args, Debug)]
struct DemoCmd {
    /// Where to write the MCAP.
    #[arg(long, short, default_value = "demo.mcap")]
    out: PathBuf,
    /// Print the JSON summary instead of text.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args, Debug)]
struct ListenCmd {
    /// A sensor's source address, optionally with the UDP port to listen on (repeatable; one
    /// socket per port). Without a port: the ports its --calib file names (Ouster metadata,
    /// Robosense angle file), else every family's default ports (Velodyne / Hesai 2368, 8308;
    /// Ouster 7502, 7503; Robosense 6699, 7788; Livox 56001–56004, 56301, 56401, 57000, 58000).
    /// Datagrams from other addresses are counted and ignored.
    #[arg(long = "sensor", value_name = "IP[:PORT]", required = true, value_parser = listen::parse_sensor)]
    sensors: Vec<(std::net::Ipv4Addr, Option<u16>)>,
    /// Output MCAP file, written continuously and finalised on SIGINT / SIGTERM / SIGHUP (omit to
    /// decode and count only).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Start a new file (OUT_0000.mcap, OUT_0001.mcap, …) every S seconds (`60`, `60s`) or
    /// every N megabytes (`500MB`); no packet is lost at the switch.
    #[arg(long, value_name = "S|MB", value_parser = listen::parse_split)]
    split_every: Option<listen::Split>,
    /// Sensor model, overriding detection (the names `decode --help` lists).
    #[arg(long)]
    model: Option<String>,
    /// Calibration file(s), as for `decode`. Ouster sensors without one: their metadata is read
    /// from http://SENSOR/api/v1/sensor/metadata (again after an init_id change).
    #[arg(long = "calib", value_name = "[ADDR=]FILE")]
    calib: Vec<String>,
    /// Before listening, fetch the angle correction of every --sensor without its own --calib
    /// over Hesai's TCP control protocol (port 9347, or PORT); for a Pandar ATX, its firetime
    /// correction too.
    #[arg(long, value_name = "PORT", num_args = 0..=1, default_missing_value = "9347")]
    hesai_ptc: Option<u16>,
    /// Livox: start the sensor before listening (SDK2: discovery, point / IMU destination,
    /// work mode; SDK1: handshake, start sampling, 1 Hz heartbeat while listening). The model
    /// from --model (SDK1 sensors need it), else SDK2 discovery.
    #[arg(long)]
    configure: bool,
    /// --configure: the sensor's address (default: the first --sensor's; a broadcast address
    /// works for SDK2 discovery).
    #[arg(long, value_name = "IP", requires = "configure")]
    device_ip: Option<std::net::Ipv4Addr>,
    /// --configure: the host UDP port commands are sent from (default: SDK2 56101 MID-360 /
    /// 56000 HAP; SDK1 any).
    #[arg(long, value_name = "PORT", requires = "configure")]
    control_port: Option<u16>,
    /// Join this multicast group on every port.
    #[arg(long, value_name = "GROUP")]
    multicast: Option<std::net::Ipv4Addr>,
    /// Interface address for --multicast.
    #[arg(long, value_name = "IP", default_value = "0.0.0.0")]
    interface: std::net::Ipv4Addr,
    #[command(flatten)]
    sweeps: SweepOpts,
    /// Threads compressing MCAP chunks (default: the machine's cores). The decode thread never
    /// waits for them: a chunk they cannot take in time is written uncompressed and counted
    /// (`output.chunks_uncompressed`); 1 = compress on the decode thread.
    #[arg(long, value_name = "N", value_parser = parse_threads, requires = "out", allow_negative_numbers = true)]
    threads: Option<usize>,
    /// Uncompressed size of an MCAP chunk, MiB (fractions allowed).
    #[arg(long, value_name = "MIB", default_value = "4", value_parser = parse_chunk_size, requires = "out", allow_negative_numbers = true)]
    chunk_size: u64,
    /// Port of the sensors' HTTP API (Ouster metadata).
    #[arg(long, default_value_t = 80)]
    api_port: u16,
    /// Receive buffer to ask for per socket, bytes (the kernel caps it at net.core.rmem_max).
    #[arg(long, default_value_t = crate::source::udp::DEFAULT_RECV_BUFFER)]
    recv_buffer: usize,
    /// Stop by itself after this many seconds.
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    /// Exit with an error if any packet was missing, dropped or malformed.
    #[arg(long)]
    strict: bool,
    /// Print one JSON summary object on stdout at the end.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    serve: serve::ServeArgs,
}

#[derive(clap::Args, Debug)]
struct ReplayCmd {
    /// Input capture (.pcap or .pcapng) or ROS bag: a bag's packets go to their family's
    /// ports (Velodyne, Hesai 2368; Ouster from the bag's metadata, else 7502 / 7503;
    /// Robosense 6699 / 7788).
    input: PathBuf,
    /// Destination IPv4 address; each datagram goes to its original destination port.
    #[arg(long)]
    to: std::net::Ipv4Addr,
    /// Added to every destination port (−65535 … 65535; a datagram whose port falls outside
    /// 0 … 65535 is skipped and counted).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true,
          value_parser = clap::value_parser!(i32).range(-65535..=65535))]
    port_offset: i32,
    /// Speed: a factor of real time (`1.0`, `10`) or `max`.
    #[arg(long, default_value = "1.0", allow_negative_numbers = true,
          value_parser = replay::parse_rate)]
    rate: crate::source::udp::Rate,
    /// Send the capture this many times (1 or more).
    #[arg(long = "loop", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..))]
    loops: u32,
    /// Send each original source address's datagrams from its own loopback address
    /// (127.0.0.1, 127.0.0.2, … in order of appearance; a bag's sensors from the 127.0.0.N
    /// `info` lists), so `listen` tells them apart.
    #[arg(long)]
    per_source_loopback: bool,
    /// Stop sending after this many seconds.
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    /// Print a JSON summary.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    bag: bag_args::BagArgs,
}

/// `--name`: a frame id and topic segment, so not empty and without `/` or spaces (ROS names:
/// letters, digits, `_`, `-`, `.`).
fn parse_name(s: &str) -> Result<String, String> {
    let ok = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
    if ok {
        Ok(s.to_string())
    } else {
        Err(format!(
            "`{s}`: expected a name of letters, digits, `_`, `-` or `.` (it is the frame id \
             and the topic prefix)"
        ))
    }
}

/// The longest `--duration` or `--timeout` taken, s (about 31 years): a longer one would
/// overflow the clock's deadline (`Instant + Duration` panics), and means "no limit" anyway.
const MAX_SECONDS: f64 = 1e9;

/// A positive number of seconds for `flag`, at most [`MAX_SECONDS`].
fn seconds(flag: &str, s: f64) -> Result<std::time::Duration, String> {
    if s > 0.0 && s <= MAX_SECONDS {
        Ok(std::time::Duration::from_secs_f64(s))
    } else {
        Err(format!(
            "{flag} {s}: expected a positive number of seconds, at most {MAX_SECONDS:e}"
        ))
    }
}

/// `--threads`: a number of threads, 1 to 1024.
fn parse_threads(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=1024).contains(&n) => Ok(n),
        _ => Err(format!("`{s}`: expected a number of threads, 1 … 1024")),
    }
}

/// `--chunk-size`: MiB, 1/64 … 1024, into bytes.
fn parse_chunk_size(s: &str) -> Result<u64, String> {
    match s.parse::<f64>() {
        Ok(m) if (1.0 / 64.0..=1024.0).contains(&m) => Ok((m * 1_048_576.0) as u64),
        _ => Err(format!("`{s}`: expected MiB, 1/64 … 1024 (e.g. 4 or 0.5)")),
    }
}

/// The default of `--threads`: the cores this process may use.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
}

fn init_logging(verbose: u8) {
    use tracing_subscriber::EnvFilter;
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter =
        EnvFilter::try_from_env("RINGSCAN_LOG").unwrap_or_else(|_| EnvFilter::new(default));
    // Colours only for a terminal: escape codes in a log file or a pipe are noise.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}

/// `--fov START:END` in degrees.
fn parse_fov(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: expected START:END in degrees"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("`{s}`: `{x}` is not a number of degrees"))
    };
    let (a, b) = (num(a)?, num(b)?);
    // A value outside a turn would be taken modulo 360, a field of view other than the one
    // written.
    for v in [a, b] {
        if !(0.0..=360.0).contains(&v) {
            return Err(format!("`{s}`: {v} is outside 0 … 360 degrees"));
        }
    }
    Ok((a, b))
}

/// Entry point of the binary: [`run()`] on the process's arguments.
pub fn main() -> ExitCode {
    ExitCode::from(run(std::env::args_os()))
}

/// Parses `args` (the program name first), runs the command and returns its exit code (0 ok,
/// 1 error, 2 usage); `python -m ringscan` calls this.
pub fn run<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let args: Vec<std::ffi::OsString> = args.into_iter().map(Into::into).collect();
    let cli = match Cli::try_parse_from(&args) {
        Ok(c) => c,
        Err(e) => {
            // --help and --version are "errors" that print to stdout and exit 0.
            let _ = e.print();
            let code = u8::try_from(e.exit_code()).unwrap_or(2);
            // A script that asked for JSON gets its error object for bad usage too (the
            // arguments did not parse, so `--json` is looked for among them as given).
            if code != 0 && args_ask_for_json(&args) {
                // clap's message up to its usage block, on one line.
                let rendered = e.to_string();
                let msg: Vec<&str> = rendered
                    .lines()
                    .take_while(|l| !l.trim().is_empty())
                    .map(str::trim)
                    .collect();
                let msg = msg.join(" ");
                let msg = msg.strip_prefix("error: ").unwrap_or(&msg);
                outln!(
                    "{}",
                    serde_json::json!({"error": msg, "kind": "usage", "exit_code": code})
                );
            }
            return code;
        }
    };
    init_logging(cli.verbose);
    let json = match &cli.command {
        Command::Decode(c) => c.json,
        Command::Info(c) => c.json,
        Command::Demo(c) => c.json,
        Command::Listen(c) => c.json,
        Command::Replay(c) => c.json,
        Command::Render(_) | Command::HesaiCalib(_) => false,
    };
    let result = match cli.command {
        Command::Decode(c) => {
            let fields_minimal = c.sweeps.fields == FieldsArg::Minimal;
            let args = DecodeArgs {
                input: c.input,
                out: c.out,
                session: c.sweeps.session(c.model, c.calib, c.port),
                fields_minimal,
                compression: c.compression,
                threads: c.threads.unwrap_or_else(default_threads),
                chunk_size: c.chunk_size,
                strict: c.strict,
                json: c.json,
                input_bytes: None,
                read_ahead: false,
                serve: c.serve,
                serve_rate: c.serve_rate,
                bag: c.bag,
            };
            run::decode_command(&args)
        }
        Command::Info(c) => {
            run::info_command(&c.input, c.model.as_deref(), &c.calib, &c.bag, c.json)
        }
        Command::Demo(c) => run::demo_command(&c.out, c.json),
        Command::Listen(c) => {
            let duration = match c.duration {
                Some(d) => match seconds("--duration", d) {
                    Ok(d) => Some(d),
                    Err(e) => {
                        eprintln!("error: {e}");
                        return 2;
                    }
                },
                None => None,
            };
            let fields_minimal = c.sweeps.fields == FieldsArg::Minimal;
            let args = listen::ListenArgs {
                sensors: c.sensors,
                out: c.out,
                split_every: c.split_every,
                session: c.sweeps.session(c.model, c.calib, None),
                fields_minimal,
                threads: c.threads.unwrap_or_else(default_threads),
                chunk_size: c.chunk_size,
                multicast: c.multicast,
                interface: c.interface,
                api_port: c.api_port,
                recv_buffer: c.recv_buffer,
                duration,
                strict: c.strict,
                json: c.json,
                serve: c.serve,
                hesai_ptc: c.hesai_ptc,
                hooks: Default::default(),
            };
            let configure = c.configure.then_some(livox_ctl::ConfigureArgs {
                device_ip: c.device_ip,
                control_port: c.control_port,
            });
            listen::listen_command(&args, configure.as_ref())
        }
        Command::Replay(c) => replay::replay_command(&replay::ReplayArgs {
            duration: match c.duration {
                Some(d) => match seconds("--duration", d) {
                    Ok(d) => Some(d),
                    Err(e) => {
                        eprintln!("error: {e}");
                        return 2;
                    }
                },
                None => None,
            },
            input: c.input,
            to: c.to,
            port_offset: c.port_offset,
            rate: c.rate,
            loops: c.loops,
            per_source_loopback: c.per_source_loopback,
            json: c.json,
            bag: c.bag,
        }),
        Command::Render(c) => render::render_command(&c),
        Command::HesaiCalib(c) => hesai_calib_command(&c),
    };
    let code = match result {
        Ok(_) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            let code = match e {
                RunError::Usage(_) => 2,
                _ => 1,
            };
            // A script that asked for JSON gets an object for a failure too; a failure the
            // run's summary reports (`--strict`) has had its object already.
            if json && !matches!(e, RunError::Reported(_)) {
                outln!("{}", e.json(code));
            }
            code
        }
    };
    let failed = STDOUT_FAILURE.lock().map(|mut f| f.take()).unwrap_or(None);
    match failed {
        // The reader went away on purpose (`| head`): what it read was right, as with `cat`.
        Some(e) if e.kind() == std::io::ErrorKind::BrokenPipe => code,
        Some(e) if code == 0 => {
            eprintln!("error: writing the output to stdout: {e}");
            1
        }
        _ => code,
    }
}

/// Whether `--json` is among the arguments as given (before a `--` that ends the options).
fn args_ask_for_json(args: &[std::ffi::OsString]) -> bool {
    args.iter()
        .skip(1)
        .take_while(|a| *a != "--")
        .any(|a| a == "--json")
}

/// The first error writing a command's output to stdout, for [`run`]'s exit code.
static STDOUT_FAILURE: std::sync::Mutex<Option<std::io::Error>> = std::sync::Mutex::new(None);

/// Writes one line of a command's output to stdout ([`outln!`]); the first failure is kept for
/// the exit code instead of panicking. The work the output reports (a file written) is done by
/// then, so nothing else stops.
pub(crate) fn write_stdout(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let written = out
        .write_fmt(args)
        .and_then(|()| out.write_all(b"\n"))
        .and_then(|()| out.flush());
    if let Err(e) = written {
        if let Ok(mut f) = STDOUT_FAILURE.lock() {
            f.get_or_insert(e);
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// `decode --help` names every model `--model` takes (the list is written out by hand).
    #[test]
    fn decode_help_names_every_model() {
        let mut cmd = super::Cli::command();
        let decode = cmd.find_subcommand_mut("decode").expect("decode");
        let help = decode.render_long_help().to_string();
        for f in crate::sensor::FAMILIES {
            for m in f.models() {
                assert!(
                    help.split(|c: char| !(c.is_alphanumeric() || c == '-'))
                        .any(|w| w == *m),
                    "{m} ({}) is not in decode --help",
                    f.name()
                );
            }
        }
    }
}
