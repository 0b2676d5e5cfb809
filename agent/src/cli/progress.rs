//! Progress of a long run on stderr: a bar on a terminal, plain lines otherwise; and a task run
//! with it.

use std::time::{Duration, Instant};

use candle_core::Device;
use indicatif::{ProgressBar, ProgressStyle};
use motion_core::constraints::checked::CheckedProgram;
use motion_core::evaluation::TaskReport;
use motion_core::export::OutputFolder;
use motion_core::generation::Event;
use motion_core::pipeline::{run_task, OpenedDatabase, TaskSettings};
use motion_core::prior::Prior;

use super::export_formats::print_exports;

/// Longest silence on a non-terminal stderr during generation.
const PLAIN_PROGRESS_EVERY: Duration = Duration::from_secs(5);

/// Shows a generation's [`Event`]s: every step on a terminal's bar; without a terminal (a log,
/// CI) a plain line on the first and last step of a stage and at least every
/// [`PLAIN_PROGRESS_EVERY`] between; notes as lines.
pub struct Progress {
    bar: ProgressBar,
    start: Instant,
    last_line: Option<Instant>,
}

impl Progress {
    /// A bar that starts now.
    pub fn new() -> Self {
        let bar = ProgressBar::new(0);
        bar.set_style(
            ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} loss {msg} ({elapsed}, eta {eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        Progress { bar, start: Instant::now(), last_line: None }
    }

    /// Shows one event.
    pub fn show(&mut self, event: Event<'_>) {
        match event {
            Event::Step { stage, round, step, steps, loss, sample } => {
                let of = sample.map_or(String::new(), |i| format!(", sample {i}"));
                self.bar.set_prefix(stage.to_owned());
                self.bar.set_length(steps as u64);
                self.bar.set_position(step as u64);
                self.bar.set_message(format!("{loss:.5} (round {round}{of})"));
                let due = self.last_line.is_none_or(|t| t.elapsed() >= PLAIN_PROGRESS_EVERY);
                if self.bar.is_hidden() && (due || step <= 1 || step == steps) {
                    self.last_line = Some(Instant::now());
                    eprintln!(
                        "{stage} round {round}{of}: step {step}/{steps} loss {loss:.5} ({:.0} s)",
                        self.start.elapsed().as_secs_f64()
                    );
                }
            }
            Event::Note(note) => self.bar.suspend(|| eprintln!("{note}")),
        }
    }

    /// Clears the bar.
    pub fn finish(self) {
        self.bar.finish_and_clear();
    }
}

/// Runs `program` with `settings` ([`motion_core::pipeline::run_task`], with `settings.database`
/// already opened when given) into `folder` with progress on stderr, and says on stderr what was
/// written.
pub fn run_with_progress(
    prior: &Prior,
    program: &CheckedProgram,
    settings: &TaskSettings,
    database: Option<&OpenedDatabase>,
    folder: OutputFolder,
    device: &Device,
) -> anyhow::Result<TaskReport> {
    let mut progress = Progress::new();
    let outcome = run_task(prior, program, settings, database, folder, device, |event| progress.show(event))?;
    progress.finish();
    print_exports(&outcome.folder, &outcome.exports, settings.exports.gif);
    eprintln!("wrote {}/{{program.json,features.npy,joints.npy,report.json,strip.png}}", outcome.folder.display());
    Ok(outcome.report)
}
