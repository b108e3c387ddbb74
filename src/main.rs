//! `instantmimic`: the command-line entry point. Everything lives in the library; this file
//! only turns an error into one clear line and a non-zero exit status.

use std::process::ExitCode;

fn main() -> ExitCode {
    match instantmimic::cli::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            // `{:#}` prints the whole context chain on one line: "loading plan x: region 3: ...".
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
