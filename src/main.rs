//! The `ringscan` command line: `decode`, `info` and `demo`.
#![forbid(unsafe_code)]

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    cli::main()
}
