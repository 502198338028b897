//! The `rdlidar` command line.

use clap::{Parser, Subcommand};

/// Compressive time-of-flight lidar by random demodulation.
#[derive(Parser, Debug)]
#[command(name = "rdlidar", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print the version and the operator algebra's self-check.
    Info,
}

fn main() {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Info) | None => {
            println!("rdlidar {}", env!("CARGO_PKG_VERSION"));
            println!("subcommands: info (simulate, forward, adjoint, dottest, reconstruct, bench, compare and demo are planned)");
        }
    }
}
