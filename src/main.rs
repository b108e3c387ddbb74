//! `instantmimic`: the command-line entry point. Everything lives in the library; this file
//! only turns an error into one clear line and a non-zero exit status (a clean stop on SIGINT
//! or SIGTERM into the shell's status for the signal, 130 or 143).

use std::process::ExitCode;

fn main() -> ExitCode {
    quiet_on_closed_stdout();
    match instantmimic::cli::run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => match err.downcast_ref::<instantmimic::cli::Stopped>() {
            // A clean stop on SIGINT/SIGTERM: the command said so already.
            Some(stopped) => ExitCode::from(stopped.exit_code()),
            None => {
                // The whole context chain on one line: "loading plan x: ...".
                eprintln!("error: {}", instantmimic::cli::error_line(&err));
                ExitCode::FAILURE
            }
        },
    }
}

/// `instantmimic plan inspect ... | head` closes stdout early; `println!` then panics. That is
/// the reader's choice, not an error: end quietly, as other command-line tools do.
fn quiet_on_closed_stdout() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(0);
        }
        default(info);
    }));
}
