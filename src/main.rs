use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = robocal::cli::Cli::parse();
    match robocal::cli::run(cli) {
        Ok(text) => {
            println!("{text}");
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::from(2)
        }
    }
}
