//! The input options of `decode`, `info` and `replay` (bags: `--topic`, `--start`, `--end`);
//! the reading itself is [`crate::source::input`].

use std::io::Read;
use std::path::Path;

use crate::source::bag::{BagOptions, TimeBound};
pub use crate::source::input::{Input, InputError};

use super::run::RunError;

/// Options that apply to bags.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct BagArgs {
    /// Bags: read only this topic (repeatable); the sensors' Ouster metadata topics are read
    /// anyway.
    #[arg(long = "topic", value_name = "TOPIC")]
    pub topics: Vec<String>,
    /// Bags: skip messages recorded before this, seconds after the bag's first message (or, above
    /// 1e9, seconds since the Unix epoch).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub start: Option<f64>,
    /// Bags: skip messages recorded after this (seconds, as --start).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub end: Option<f64>,
}

impl BagArgs {
    fn given(&self) -> bool {
        !self.topics.is_empty() || self.start.is_some() || self.end.is_some()
    }

    fn options(&self) -> Result<BagOptions, RunError> {
        for (name, v) in [("--start", self.start), ("--end", self.end)] {
            if v.is_some_and(|s| !s.is_finite() || s < 0.0) {
                return Err(RunError::Usage(format!(
                    "{name}: expected a non-negative number of seconds"
                )));
            }
        }
        if let (Some(a), Some(b)) = (self.start, self.end) {
            if a > b {
                return Err(RunError::Usage(format!(
                    "--start {a} / --end {b}: the window ends before it starts"
                )));
            }
        }
        Ok(BagOptions {
            topics: self.topics.clone(),
            start: self.start.map(TimeBound::from_seconds),
            end: self.end.map(TimeBound::from_seconds),
        })
    }
}

/// Opens `path` as a bag when its bytes say so, else as a capture; the bag options on anything
/// but a bag are a usage error.
pub fn open(path: &Path, bag_args: &BagArgs) -> Result<Input<Box<dyn Read>>, RunError> {
    open_with(path, bag_args, false)
}

/// [`open`], with a capture read ahead on a thread of its own when `read_ahead`
/// ([`crate::source::input::open_with`]).
pub fn open_with(
    path: &Path,
    bag_args: &BagArgs,
    read_ahead: bool,
) -> Result<Input<Box<dyn Read>>, RunError> {
    let not_a_bag = || {
        RunError::Usage(format!(
            "--topic / --start / --end: {} is not a bag",
            path.display()
        ))
    };
    // The input is opened more than once (its kind is told from its first bytes, and the
    // sensors are counted before the output is named), so a pipe would be read from where
    // the last reader left it: refused with the reason, not with bytes from its middle.
    let stream = |what: &str| {
        RunError::Usage(format!(
            "{}: {what}, not a file: ringscan reads its input from the start more than once \
             (to tell its format and count its sensors); save the stream to a file first",
            path.display()
        ))
    };
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() && !m.is_dir() => return Err(stream("a pipe, socket or device")),
        Err(_) if path.as_os_str() == "-" => return Err(stream("standard input")),
        _ => {}
    }
    match crate::source::input::open_with(path, bag_args.options()?, read_ahead) {
        Ok(input) if bag_args.given() && input.bag().is_none() => Err(not_a_bag()),
        Ok(input) => Ok(input),
        Err(InputError::Pcap(_) | InputError::Unrecognised { .. }) if bag_args.given() => {
            Err(not_a_bag())
        }
        Err(err) => Err(RunError::Source {
            path: path.display().to_string(),
            err,
        }),
    }
}
