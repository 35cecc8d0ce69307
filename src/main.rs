use std::io::Write;

use clap::Parser;

/// Print to standard output; a reader that went away (`| head`) is not an error of ours.
fn print(text: &str) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{text}").and_then(|_| out.flush());
}

fn main() -> std::process::ExitCode {
    let cli = robocal::cli::Cli::parse();
    match robocal::cli::run(cli) {
        Ok(text) => {
            // Empty: the command wrote its output itself (`filter` writes the program's bytes).
            if !text.is_empty() {
                print(&text);
            }
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            if let Some(out) = e.output.as_deref().filter(|o| !o.is_empty()) {
                print(out);
            }
            eprintln!("error: {e}");
            std::process::ExitCode::from(e.exit_status())
        }
    }
}
