//! Command-line layer: raw arguments (clap) → validated options → library calls.

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// Render what an observer sees through a layered (arctic) atmosphere, from real radiosonde
/// soundings or synthetic paper-style layers.
#[derive(Debug, Parser)]
#[command(name = "ghostship", version, about, long_about = None)]
pub struct Cli {
    /// Print nothing but errors (no summaries, no progress bars).
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Ingest a sounding (or synthetic atmosphere), fit it, detect layers and ducts, and compute n(h).
    Profile(ProfileArgs),
}

/// Arguments of `ghostship profile`.
#[derive(Debug, clap::Args)]
pub struct ProfileArgs {
    /// Sounding file (CSV, Wyoming, IGRA2) or synthetic atmosphere (.toml).
    pub input: PathBuf,
}

/// Parse the process arguments.
pub fn parse() -> Cli {
    Cli::parse()
}

/// Run one command.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Profile(_args) => anyhow::bail!("`profile` is not built yet"),
    }
}
