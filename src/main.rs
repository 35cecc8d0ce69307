use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = robocal::cli::Cli::parse();
    match robocal::cli::run(cli) {
        Ok(text) => {
            println!("{text}");
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            if let Some(out) = e.output.as_deref().filter(|o| !o.is_empty()) {
                println!("{out}");
            }
            eprintln!("error: {e}");
            std::process::ExitCode::from(e.exit_status())
        }
    }
}
