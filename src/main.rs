//! The `ringscan` command line: `decode`, `info`, `demo`, `listen` and `replay`.
#![forbid(unsafe_code)]

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    cli::main()
}
