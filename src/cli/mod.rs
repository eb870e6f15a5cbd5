//! Command-line front end: clap commands, progress, exit codes. No algorithms live here.

mod pipeline;
mod render;
mod run;
mod sensors;

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
    /// Decode a pcap / pcapng capture into sweeps, written to MCAP.
    Decode(DecodeCmd),
    /// Tell what a capture holds: sensors, models, return modes, ports, duration, sweeps, loss.
    Info(InfoCmd),
    /// Decode the built-in example capture (a simulated VLP-16) and write demo.mcap.
    Demo(DemoCmd),
    /// Draw a bird's-eye picture of one sweep of an MCAP written with `--pipeline`.
    Render(render::RenderCmd),
}

/// Point cloud message layout.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum FormatArg {
    /// foxglove.PointCloud (protobuf).
    Foxglove,
    /// sensor_msgs/msg/PointCloud2 (CDR).
    Ros2,
}

/// Ouster CRC checking.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum CrcArg {
    /// Check where the firmware writes valid CRCs (≥ 2.5, not FUSA).
    Auto,
    /// Always check (packets with a bad CRC are dropped and counted).
    On,
    /// Never check.
    Off,
}

/// Which point fields are written.
#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum FieldsArg {
    /// x, y, z, intensity, t, ring, return.
    Default,
    /// The default fields plus every extra field the sensor has (none for Velodyne).
    All,
}

#[derive(clap::Args, Debug)]
struct DecodeCmd {
    /// Input capture (.pcap or .pcapng).
    input: PathBuf,
    /// Output MCAP file (omit to decode and count only).
    #[arg(long, short)]
    out: Option<PathBuf>,
    /// Sensor model, overriding detection: vlp16, puck-hires, hdl32e, vlp32c, hdl64e-s2,
    /// hdl64e-s3, vls128.
    #[arg(long)]
    model: Option<String>,
    /// Calibration file: ROS velodyne yaml, VeloView xml or HDL-64E db.xml; `ADDR=FILE` gives
    /// it to the sensor at that source address only. Repeatable.
    #[arg(long = "calib", value_name = "[ADDR=]FILE")]
    calib: Vec<String>,
    /// Sensor name (frame id and topic prefix); only with a single sensor.
    #[arg(long)]
    name: Option<String>,
    /// Only data packets sent to this UDP port.
    #[arg(long)]
    port: Option<u16>,
    /// Azimuth at which sweeps are cut, degrees.
    #[arg(long, default_value_t = 0.0)]
    cut_angle: f64,
    /// Drop points closer than this, metres.
    #[arg(long)]
    min_range: Option<f32>,
    /// Drop points farther than this, metres.
    #[arg(long)]
    max_range: Option<f32>,
    /// Point fields written.
    #[arg(long, value_enum, default_value_t = FieldsArg::Default)]
    fields: FieldsArg,
    /// Message layout.
    #[arg(long, value_enum, default_value_t = FormatArg::Foxglove)]
    format: FormatArg,
    /// Also write every UDP payload to `/raw`, so the drive can be decoded again later.
    #[arg(long)]
    raw: bool,
    /// Ouster footer CRC-64 check: `auto` = for firmware ≥ 2.5 (not FUSA), `on`, `off`.
    #[arg(long, value_enum, default_value_t = CrcArg::Auto)]
    crc: CrcArg,
    /// Exit with an error if any packet was missing, dropped or malformed.
    #[arg(long)]
    strict: bool,
    /// Print one JSON summary object on stdout at the end.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    pipeline: pipeline::PipelineArgs,
}

#[derive(clap::Args, Debug)]
struct InfoCmd {
    /// Input capture (.pcap or .pcapng).
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

fn init_logging(verbose: u8) {
    use tracing_subscriber::EnvFilter;
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter =
        EnvFilter::try_from_env("RINGSCAN_LOG").unwrap_or_else(|_| EnvFilter::new(default));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}

/// Entry point: parse, run, map errors to exit codes (0 ok, 1 error, 2 usage).
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbose);
    let result = match cli.command {
        Command::Decode(c) => {
            let args = DecodeArgs {
                input: c.input,
                out: c.out,
                model: c.model,
                calib: c.calib,
                name: c.name,
                port: c.port,
                cut_angle_deg: c.cut_angle,
                min_range: c.min_range,
                max_range: c.max_range,
                fields_all: c.fields == FieldsArg::All,
                format: c.format,
                raw: c.raw,
                strict: c.strict,
                crc: match c.crc {
                    CrcArg::Auto => None,
                    CrcArg::On => Some(true),
                    CrcArg::Off => Some(false),
                },
                json: c.json,
                input_bytes: None,
                pipeline: c.pipeline,
            };
            run::decode_command(&args)
        }
        Command::Info(c) => run::info_command(&c.input, c.model.as_deref(), &c.calib, c.json),
        Command::Demo(c) => run::demo_command(&c.out, c.json),
        Command::Render(c) => render::render_command(&c),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            match e {
                RunError::Usage(_) => ExitCode::from(2),
                _ => ExitCode::from(1),
            }
        }
    }
}
