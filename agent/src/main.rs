//! `mogen`: constrained human motion generation from the command line.

mod cli;
mod commands;

use agent::paths;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// mimalloc keeps freed pages for reuse: the DNO loop allocates and frees tens of MB of
/// activations per step, which glibc's malloc hands back to the kernel and faults in again.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// `mi_option_purge_delay` in mimalloc.h's `mi_option_e` (the same index in mimalloc 2 and 3;
/// the sys crate names no constant for it): how long freed memory waits before it is
/// returned to the OS, in ms (mimalloc 3's default 1000, −1 never).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Never returns freed pages to the OS. A DNO step frees its activations during the backward
/// pass and allocates them again in the next forward pass; with the default delay mimalloc
/// still hands some back, which the next steps fault in and the kernel zeroes again
/// (measured: 0.6–0.8 s of a 24 s Task-1 sample). The process keeps its peak
/// footprint instead (about 130 MiB for a DNO sample).
fn keep_freed_pages() {
    // SAFETY: `mi_option_set` only stores an integer option; it is called before any thread
    // is started, with an index of mimalloc's option enum (checked by a test against the
    // option's documented default).
    #[allow(unsafe_code)]
    unsafe {
        libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1);
    }
}

/// Constrained human motion generation driven by language.
///
/// `mogen "walk forwards through a 0.4 m wide gap and stop 5 m ahead"`: an LLM writes the
/// constraint program and its relational parse, then the motions are generated. Without an LLM
/// endpoint the recorded replies answer (shipped inside the binary; fixtures/llm/recorded in the
/// source tree). The defaults are unpacked on first use into $MOGEN_DATA_DIR, else
/// $XDG_DATA_HOME/mogen, else ~/.local/share/mogen.
///
/// Conventions: y up, metres, seconds, +x is the character's left, motions start facing +z,
/// 20 frames per second, the 22-joint SMPL/HumanML3D skeleton.
#[derive(Parser)]
#[command(
    name = "mogen",
    version,
    about,
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true,
    arg_required_else_help = true
)]
struct Cli {
    #[command(flatten)]
    task: commands::task::TaskArgs,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Motion data: the motion corpus (build, stats, pictures) and the training/retrieval database.
    #[command(subcommand)]
    Data(commands::data::DataCommand),
    /// Train the motion prior on the corpus or your own database, or the text–motion evaluator
    /// (resumable; progress and loss on stderr).
    Train(commands::train::TrainArgs),
    /// Unconstrained motions from the prior for a text prompt (npy, PNG strip, BVH, GLB, viewer
    /// page).
    Sample(commands::sample::SampleArgs),
    /// Generate motions for a constraint program file (npy, JSON report, PNG strip, BVH, GLB,
    /// viewer page).
    Run(commands::run::RunArgs),
    /// RG-DNO's constraint-based retrieval for a program: the crops of the retrieval database
    /// (by default the corpus's train split) that best satisfy its retrieval set C_R; when the
    /// prompt names a skill other than walking (a crawl, a sit, a jump, ...), only the crops
    /// that do it, if any do.
    Retrieve(commands::retrieve::RetrieveArgs),
    /// Motions already made (an output folder or a joints.npy) to BVH, GLB (skinned figure and
    /// the task's scene) and the self-contained 3-D viewer page.
    Export(commands::export::ExportArgs),
    /// Print the JSON Schema of constraint programs (what `run` accepts).
    Schema,
    /// Reports: `prior` measures unconstrained samples per skill family against held-out capture
    /// (or per label against a database).
    #[command(subcommand)]
    Report(ReportCommand),
    /// Benchmarks: `prior` (denoiser and DNO-step speed), `tasks` (results table), `dno` (full DNO run time),
    /// `retrieval` (RG-DNO's retrieval over the whole database: seconds, memory).
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Debug, Subcommand)]
enum BenchCommand {
    /// Denoiser forward, ddim sampling, unrolled DNO step at batch 1 and 8; peak memory.
    Prior(commands::bench::BenchArgs),
    /// Every shipped task × {unconstrained, IK, IK+Reg, DNO}: results table (markdown + JSON).
    Tasks(Box<commands::bench_tasks::BenchTasksArgs>),
    /// Wall time of a full DNO run (500 steps) at batch 1 and 8.
    Dno(commands::bench_dno::BenchDnoArgs),
    /// RG-DNO's retrieval for one task over the whole retrieval database (by default the
    /// corpus's train split): seconds per query, bytes held.
    Retrieval(commands::bench_retrieval::BenchRetrievalArgs),
}

#[derive(Debug, Subcommand)]
enum ReportCommand {
    /// Unconstrained samples per skill family against the corpus's held-out capture: action
    /// detectors, gait, foot skate, acceleration, floor, memorisation, strips (`--database`: per
    /// label against a database).
    Prior(Box<commands::report::ReportArgs>),
    /// Plot a training loss curve from `mogen train --loss-csv`.
    Loss(commands::report::LossArgs),
}

/// Runs the command; an error is printed as its chain of causes (`what: why: ...`, a cause
/// whose message its parent already quotes is not repeated), without a backtrace even when
/// `RUST_BACKTRACE` is set, and the exit status is 1.
///
/// Library errors (candle's among them) capture a backtrace into their message when
/// `RUST_BACKTRACE` is set, unless `RUST_LIB_BACKTRACE` says otherwise: it is set to 0 here
/// when the user has not set it, so a damaged prior file reads as one line while a panic still
/// prints its backtrace.
fn main() -> ExitCode {
    if std::env::var_os("RUST_LIB_BACKTRACE").is_none() {
        // Before any thread starts and before any backtrace is captured.
        std::env::set_var("RUST_LIB_BACKTRACE", "0");
    }
    keep_freed_pages();
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            let mut message = String::new();
            for cause in error.chain().map(ToString::to_string) {
                if !message.contains(&cause) {
                    if !message.is_empty() {
                        message.push_str(": ");
                    }
                    message.push_str(&cause);
                }
            }
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

/// Runs the command on a rayon pool with one worker per core (rayon's default), so the
/// numeric kernels' parallel phases start on a worker instead of handing every phase over
/// from the main thread and waking a worker for it.
fn run() -> anyhow::Result<()> {
    rayon::ThreadPoolBuilder::new().build()?.install(run_command)
}

fn run_command() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()))
        .with_writer(std::io::stderr)
        .without_time()
        .init();
    let cli = Cli::parse();
    // Every command's defaults come from here; without them a default path would fail later
    // with a less helpful message.
    paths::fixtures()?;
    let Some(command) = cli.command else { return commands::task::run(cli.task) };
    match command {
        Command::Data(cmd) => commands::data::run(cmd),
        Command::Train(args) => commands::train::run(args),
        Command::Sample(args) => commands::sample::run(args),
        Command::Run(args) => commands::run::run(args),
        Command::Retrieve(args) => commands::retrieve::run(args),
        Command::Export(args) => commands::export::run(args),
        Command::Schema => {
            println!("{}", serde_json::to_string_pretty(&motion_core::program::json_schema())?);
            Ok(())
        }
        Command::Report(ReportCommand::Prior(args)) => commands::report::run(*args),
        Command::Report(ReportCommand::Loss(args)) => commands::report::run_loss(args),
        Command::Bench(BenchCommand::Prior(args)) => commands::bench::run(args),
        Command::Bench(BenchCommand::Tasks(args)) => commands::bench_tasks::run_tasks(*args),
        Command::Bench(BenchCommand::Dno(args)) => commands::bench_dno::run(args),
        Command::Bench(BenchCommand::Retrieval(args)) => commands::bench_retrieval::run(args),
    }
}

#[cfg(test)]
mod tests {
    use super::MI_OPTION_PURGE_DELAY;

    /// The index names mimalloc's purge delay: no other option defaults to 1000.
    #[test]
    fn purge_delay_index_is_mimallocs() {
        #[allow(unsafe_code)]
        // SAFETY: reads an integer option.
        let delay = unsafe { libmimalloc_sys::mi_option_get(MI_OPTION_PURGE_DELAY) };
        assert_eq!(delay, 1000);
    }
}
