//! `robobus`: drive and simulate wCK servos and WHJ joints from the command line.
//!
//! One module per subcommand; this file only parses and dispatches.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod sim_wck;
mod sim_whj;

/// Drive and simulate RoboBuilder wCK servos and RealMan WHJ joints.
#[derive(Debug, Parser)]
#[command(name = "robobus", version, about, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a simulated bus that other programs can talk to like real hardware.
    #[command(subcommand)]
    Sim(SimCommand),
}

#[derive(Debug, Subcommand)]
enum SimCommand {
    /// Simulated wCK servos behind a pseudo-terminal (a serial port any program can open).
    Wck(sim_wck::Args),
    /// Simulated WHJ joints on a virtual CAN FD bus (python-can UDP multicast or SocketCAN).
    Whj(sim_whj::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        Command::Sim(SimCommand::Wck(args)) => sim_wck::run(&args),
        Command::Sim(SimCommand::Whj(args)) => sim_whj::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("robobus: error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
