//! The `ringscan` command line: `decode`, `info`, `demo`, `listen` and `replay`.
#![forbid(unsafe_code)]

use std::process::ExitCode;

fn main() -> ExitCode {
    ringscan::cli::main()
}
