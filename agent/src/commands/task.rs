//! `mogen "<task>"`: a task in words → constraint program → relational parse → motions.

use std::path::PathBuf;
use std::time::Duration;

use agent::llm::{
    escape_controls, ApiKey, ClientConfig, Llm, LlmSettings, OutputMode, ReplySource, RetryPolicy, DEFAULT_MODEL,
};
use agent::plan::{plan_from_file, plan_task, PlanSettings, PlannedTask};
use candle_core::Device;
use clap::Args;
use motion_core::export::OutputFolder;

use crate::cli::flags;
use crate::cli::generation_args::{GenerationArgs, MethodArg};
use crate::cli::load::{device, load_prior_and_database};
use crate::cli::progress::run_with_progress;
use agent::paths;

/// No `Debug`: the arguments hold the API key.
#[derive(Args)]
pub struct TaskArgs {
    /// The task in words, e.g. "walk forwards through a 0.4 m wide gap and stop 5 m ahead".
    #[arg(required_unless_present = "program")]
    task: Option<String>,
    /// A constraint program written by hand (JSON, like fixtures/tasks/*.json) instead of a task in
    /// words; its relational parse is used when it has one.
    #[arg(long, value_name = "FILE", conflicts_with = "task")]
    program: Option<PathBuf>,
    /// Stop after validation: print the program, the relational parse and the constraint groups.
    #[arg(long)]
    dry_run: bool,
    /// Print the program before generating.
    #[arg(long)]
    show_program: bool,
    /// Generation method: RG-DNO by default, which falls back to DNO (saying why) when the task
    /// has no relational parse or no database motion is retrieved.
    #[arg(long, short, value_enum, default_value_t = MethodArg::RgDno)]
    method: MethodArg,
    #[command(flatten)]
    generation: GenerationArgs,
    /// Output folder: program.json, features.npy, joints.npy, report.json, strip.png,
    /// `sample_<i>/motion.bvh` and .glb, viewer.html (3-D, offline), export.json.
    #[arg(long, short, default_value = "out/task")]
    out: PathBuf,
    /// Repair rounds per LLM stage when an answer is invalid.
    #[arg(long, default_value_t = PlanSettings::default().max_repairs)]
    max_repairs: u32,
    /// RG-DNO's retrieval confidence s in [0, 1]: below 0.5 the most difficult constraint is also
    /// fitted from random noise.
    #[arg(long, default_value_t = PlanSettings::default().retrieval_confidence, value_parser = unit_interval)]
    retrieval_confidence: f64,
    #[command(flatten)]
    llm: LlmArgs,
}

/// Where the LLM is. With no endpoint configured, replies are replayed from the recordings.
#[derive(Args)]
#[command(next_help_heading = "LLM")]
struct LlmArgs {
    /// Base URL of an OpenAI-compatible API (vLLM `http://localhost:8000/v1`, Ollama
    /// `http://localhost:11434/v1`, llama.cpp `http://localhost:8080/v1`, `https://api.deepseek.com/v1`).
    #[arg(long, env = "OPENAI_BASE_URL", hide_env_values = true)]
    base_url: Option<String>,
    /// Model name.
    #[arg(long, env = "OPENAI_MODEL", default_value = DEFAULT_MODEL)]
    model: String,
    /// API key (alone: OpenAI's endpoint).
    #[arg(long, env = "OPENAI_API_KEY", hide_env_values = true)]
    api_key: Option<String>,
    /// Write every exchange with the endpoint to the recordings folder.
    #[arg(long, conflicts_with = "replay")]
    record: bool,
    /// Answer from the recordings folder only (no network), even with an endpoint configured.
    #[arg(long)]
    replay: bool,
    /// The recordings folder.
    #[arg(long, value_name = "DIR", default_value_os_t = paths::default_recordings())]
    recordings: PathBuf,
    /// Structured output: json-schema (strict), json-object (schema in the prompt) or prompt-only.
    /// Default: what the server supports, stepping down when it rejects a mode.
    #[arg(long, value_enum)]
    structured_output: Option<OutputMode>,
    /// Seconds one request may take.
    #[arg(long, value_name = "SECONDS", default_value_t = ClientConfig::default().request_timeout.as_secs())]
    timeout: u64,
    /// Retries of a request on 429, 5xx, connection errors and timeouts.
    #[arg(long, default_value_t = RetryPolicy::default().max_retries)]
    retries: u32,
    /// Sampling temperature.
    #[arg(long, default_value_t = 0.0, value_parser = flags::temperature)]
    temperature: f64,
    /// Reply token limit (default: the server's).
    #[arg(long)]
    max_tokens: Option<u32>,
}

impl LlmArgs {
    fn settings(&self) -> LlmSettings {
        let source = match (self.record, self.replay) {
            (true, _) => Some(ReplySource::Record),
            (_, true) => Some(ReplySource::Replay),
            _ => None,
        };
        let defaults = ClientConfig::default();
        LlmSettings {
            base_url: self.base_url.clone().filter(|url| !url.trim().is_empty()),
            api_key: self.api_key.clone().and_then(ApiKey::new),
            model: self.model.clone(),
            source,
            recordings: self.recordings.clone(),
            client: ClientConfig {
                request_timeout: Duration::from_secs(self.timeout),
                retry: RetryPolicy { max_retries: self.retries, ..defaults.retry.clone() },
                ..defaults
            },
            output: self.structured_output,
            temperature: Some(self.temperature),
            max_tokens: self.max_tokens,
        }
    }
}

fn unit_interval(text: &str) -> Result<f64, String> {
    let value: f64 = text.parse().map_err(|error| format!("{error}"))?;
    if (0.0..=1.0).contains(&value) {
        Ok(value)
    } else {
        Err(format!("{value} is not in [0, 1]"))
    }
}

pub fn run(args: TaskArgs) -> anyhow::Result<()> {
    // A bad --out fails before the LLM and the generator run.
    let out = if args.dry_run { None } else { Some(OutputFolder::create(&args.out)?) };
    let device = device()?;
    let planned = match (&args.program, &args.task) {
        (Some(path), _) => plan_from_file(path, &device)?,
        (None, Some(task)) => plan_words(task, &args, &device)?,
        (None, None) => anyhow::bail!("give a task in words or --program FILE"),
    };
    if args.show_program || args.dry_run {
        println!("{}", planned.program.program().to_json_pretty()?);
    }
    print_plan(&planned);
    let Some(out) = out else {
        println!("dry run: the program is valid; stopping before generation");
        return Ok(());
    };
    // RG-DNO, through the plan's relational parse and Algorithm 1's groups, falls back to DNO and
    // says why without them.
    let settings = args.generation.settings(args.method.into())?;
    let (prior, database) = load_prior_and_database(&args.generation.prior, &planned.program, &settings, &device)?;
    let report = run_with_progress(&prior, &planned.program, &settings, database.as_ref(), out, &device)?;
    print!("{}", report.summary());
    Ok(())
}

/// The two LLM stages for `task`; the program is checked and compiled on `device`.
fn plan_words(task: &str, args: &TaskArgs, device: &Device) -> anyhow::Result<PlannedTask> {
    let settings = args.llm.settings();
    let endpoint_configured = settings.base_url.is_some() || settings.api_key.is_some();
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    runtime.block_on(async {
        let llm = Llm::connect(settings)?;
        if llm.source() == ReplySource::Replay && !endpoint_configured {
            eprintln!(
                "no LLM endpoint configured (--base-url / OPENAI_BASE_URL, --api-key / OPENAI_API_KEY): \
                 replaying recorded replies"
            );
        }
        eprintln!("LLM: {}", llm.describe());
        let plan = PlanSettings { max_repairs: args.max_repairs, retrieval_confidence: args.retrieval_confidence };
        Ok(plan_task(task, &llm, &plan, device).await?)
    })
}

/// The relational parse and the groups of Algorithm 1, on stdout.
fn print_plan(planned: &PlannedTask) {
    let program = planned.program.program();
    println!(
        "program: {} constraint(s), {} frames, prompt {:?}",
        program.constraints.len(),
        program.frames,
        program.text
    );
    for constraint in &program.constraints {
        let description = constraint.description.as_deref().unwrap_or("(no description)");
        println!("  {}: {}", constraint.id, escape_controls(description));
    }
    let Some(parse) = &program.relational_parse else {
        println!("no relational parse: every constraint is fitted from random noise");
        return;
    };
    println!(
        "relational parse: most difficult {}; connected {}; conflicting {}; retrieval confidence {}",
        parse.most_difficult,
        set(&parse.connected),
        set(&parse.conflicting),
        parse.retrieval_confidence
    );
    if let Some(analysis) = &planned.analysis {
        println!("  analysis: {}", escape_controls(analysis));
    }
    if let Some(groups) = &planned.groups {
        println!(
            "Algorithm 1: C_R = {}, C1 = {}, C2 = {}",
            set(&groups.retrieval),
            set(&groups.random_noise),
            set(&groups.retrieved_noise)
        );
    }
}

fn set(ids: &[String]) -> String {
    format!("{{{}}}", ids.join(", "))
}
