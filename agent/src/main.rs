//! `mogen`: constrained human motion generation from the command line.

mod commands;
mod paths;

use clap::{Parser, Subcommand};

/// Constrained human motion generation driven by language.
///
/// Conventions: y up, metres, seconds, +x is the character's left, motions start facing +z,
/// 20 frames per second, the 22-joint SMPL/HumanML3D skeleton.
#[derive(Debug, Parser)]
#[command(name = "mogen", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Motion data: import mocap, build the training/retrieval database.
    #[command(subcommand)]
    Data(commands::data::DataCommand),
}

fn main() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()))
        .with_writer(std::io::stderr)
        .without_time()
        .init();
    let cli = Cli::parse();
    match cli.command {
        Command::Data(cmd) => commands::data::run(cmd),
    }
}
