//! Command-line layer: raw arguments (clap; bad values are usage errors, exit status 2, through
//! value parsers) → the typed requests of the library's jobs layer (`ghostship::jobs`) → their
//! products, printed or written. One file per command: [`profile`] (stages 1–3 and their
//! report), [`trace`] (the transfer analysis), [`render`] (scenes to images), [`sequence`] (sweeps of the sun, the
//! observer, a scene key or the air between soundings), [`compare`]
//! (measured against synthetic layers), [`pipeline`] (batch
//! runs of all three, shards and merge) and [`bench`] (time against error, the stress suite).
//! Errors go back to `main` as one `anyhow` chain.

pub mod bench;
pub mod compare;
pub mod pipeline;
pub mod profile;
pub mod render;
pub mod sequence;
pub mod survey;
pub mod trace;

use std::io::Write;

use anyhow::Context;
use clap::{Parser, Subcommand};

/// Turn real radiosonde soundings (or synthetic paper-style layers) into the refractive
/// atmosphere, ray fans and transfer curves behind arctic mirages: superior and inferior
/// mirages, Fata Morgana, the Novaya Zemlya sun.
///
/// An ATMOSPHERE is a sounding file (normalised CSV, University of Wyoming TEXT:LIST or TEXT:CSV,
/// IGRA2; the format is read from the content), a synthetic layered atmosphere (`*.toml`), or
/// `us1976` (the U.S. Standard Atmosphere 1976). Units are in the option names: `_m` metres,
/// `_nm` nanometres, `_deg` degrees.
#[derive(Debug, Parser)]
#[command(name = "ghostship", version, about, long_about)]
pub struct Cli {
    /// Print nothing but errors and the command's data output (no summaries of written files,
    /// no progress bars).
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Ingest a sounding (or synthetic atmosphere), fit it, find inversions, ducts and refractive
    /// layers, and write n(h): prints a summary and writes profile.csv, layers.json, profile.png.
    Profile(profile::ProfileArgs),
    /// Trace a fan of rays from an observer: heights at target distances, images of targets,
    /// apparent horizons, trapped rays (JSON or CSV on stdout, optional plot).
    Trace(trace::TraceArgs),
    /// Render what a camera sees through the scene's atmosphere: horizon, sea, sky, cards and
    /// sun, to PNG and/or EXR.
    Render(render::RenderArgs),
    /// Render a sequence of frames sweeping the sun (true elevation FROM:TO:STEP, or its position
    /// over a UTC time span), the observer's height, any numeric scene key, or the air between
    /// two soundings: numbered PNG (and EXR) frames, an animated GIF, an MP4 when ffmpeg is on
    /// the PATH, a frame index CSV and plots.
    Sequence(Box<sequence::SequenceArgs>),
    /// Measured against synthetic: trace and render a scene through a sounding and through
    /// synthetic layers (by default fitted to it), and report what differs: images of each
    /// target, horizons, trapped rays, ducts, RMSE/SSIM; writes compare.json and figures.
    Compare(compare::CompareArgs),
    /// Survey a sounding archive (IGRA2 records, Wyoming pages, folders, globs): per sounding its
    /// inversions, ducts, horizon dip and what an observer would see of a target and the sun;
    /// writes survey.csv, survey.parquet, survey.json and plots.
    Survey(survey::SurveyArgs),
    /// Join the parts of a survey split with `survey --shard K/N` (or a pipeline's `parts`) into
    /// the table and plots one unsplit run writes.
    SurveyMerge(survey::SurveyMergeArgs),
    /// Batch runs described by a pipeline file.
    Pipeline(pipeline::PipelineArgs),
    /// Benchmarks: `bench accuracy` measures the tracer's error against its time per ray and
    /// writes BENCHMARKS.md with a log-log plot; `bench stress` measures the stress suite's
    /// error against tolerance and writes STRESS.md with a log-log plot.
    Bench(bench::BenchArgs),
}

/// Parse the process arguments (usage errors print clap's message and exit with status 2).
pub fn parse() -> Cli {
    Cli::parse()
}

/// Run one command.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Profile(args) => profile::run(args, cli.quiet),
        Command::Trace(args) => trace::run(args, cli.quiet),
        Command::Render(args) => render::run(args, cli.quiet),
        Command::Sequence(args) => sequence::run(*args, cli.quiet),
        Command::Compare(args) => compare::run(args, cli.quiet),
        Command::Survey(args) => survey::run(args, cli.quiet),
        Command::SurveyMerge(args) => survey::merge(args, cli.quiet),
        Command::Pipeline(args) => pipeline::run(args, cli.quiet),
        Command::Bench(args) => bench::run(args, cli.quiet),
    }
}

/// Write `text` to standard output through one lock, and flush it. Every command's data output
/// goes through here (never `println!`, which panics on a closed pipe). A closed pipe — the
/// reader, e.g. `head -c 10`, has stopped reading — is not an error: the rest of the text is
/// dropped, and the command goes on with its files and exits with status 0, silently.
pub fn print_stdout(text: &str) -> anyhow::Result<()> {
    write_quietly(&mut std::io::stdout().lock(), text.as_bytes())
        .context("cannot write to standard output")
}

/// `text` to `out`, flushed; a broken pipe counts as written.
fn write_quietly(out: &mut impl Write, text: &[u8]) -> std::io::Result<()> {
    match out.write_all(text).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}

/// Write each product to its path (atomically, through the jobs layer's writer) and, unless
/// `quiet`, say so on stderr.
pub fn write_files(
    files: &[(std::path::PathBuf, ghostship::jobs::Product)],
    quiet: bool,
) -> anyhow::Result<()> {
    ghostship::jobs::writer::write_products_to(
        files.iter().map(|(p, product)| (p.as_path(), product)),
    )?;
    if !quiet {
        for (path, _) in files {
            eprintln!("wrote {}", path.display());
        }
    }
    Ok(())
}

/// Write `products` into `dir` under their names (see [`write_files`]).
pub fn write_into(
    dir: &std::path::Path,
    products: &[ghostship::jobs::Product],
    quiet: bool,
) -> anyhow::Result<()> {
    let files: Vec<_> = products
        .iter()
        .map(|p| (dir.join(&p.name), p.clone()))
        .collect();
    write_files(&files, quiet)
}

/// The error and its causes on one line, `outer: inner: …` (like anyhow's `{:#}`), leaving out a
/// cause whose text the message so far already ends with: several stage errors print their
/// source inside their own message *and* expose it as the source, which would repeat it.
pub fn error_chain(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let part = cause.to_string();
        if text.is_empty() {
            text = part;
        } else if !text.ends_with(&part) {
            text.push_str(": ");
            text.push_str(&part);
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("cannot read x: {source}")]
    struct Repeats {
        #[source]
        source: std::io::Error,
    }

    /// A writer whose reader has gone after `room` bytes.
    struct ClosedAfter {
        room: usize,
        kind: std::io::ErrorKind,
    }

    impl Write for ClosedAfter {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if self.room == 0 {
                return Err(std::io::Error::from(self.kind));
            }
            let n = buf.len().min(self.room);
            self.room -= n;
            Ok(n)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_closed_pipe_is_a_quiet_end_other_errors_are_not() {
        let mut pipe = ClosedAfter {
            room: 4,
            kind: std::io::ErrorKind::BrokenPipe,
        };
        assert!(write_quietly(&mut pipe, b"0123456789").is_ok());
        assert!(write_quietly(&mut pipe, b"more").is_ok());
        let mut full = ClosedAfter {
            room: 4,
            kind: std::io::ErrorKind::StorageFull,
        };
        assert!(write_quietly(&mut full, b"0123456789").is_err());
    }

    #[test]
    fn chain_drops_repeated_causes_only() {
        let io = || std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        let err = anyhow::Error::new(Repeats { source: io() }).context("loading");
        assert_eq!(error_chain(&err), "loading: cannot read x: gone");
        let err = anyhow::Error::new(io()).context("loading");
        assert_eq!(error_chain(&err), "loading: gone");
    }
}
