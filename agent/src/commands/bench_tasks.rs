//! `mogen bench tasks`: every shipped task × every method, written as a results table
//! (markdown + JSON).

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use motion_core::evaluation::TaskReport;
use motion_core::export::{write_atomically, OutputFolder};
use motion_core::generation::method::{GenerationConfig, Method};
use motion_core::generation::schedule::Schedule;
use motion_core::pipeline::{retrieves, OpenedDatabase, TaskSettings};
use motion_core::prior::PriorIdentity;
use serde::{Deserialize, Serialize};

use crate::cli::generation_args::{GenerationArgs, MethodArg};
use crate::cli::load::{device, load_prior, load_program};
use crate::cli::progress::run_with_progress;
use agent::paths;

#[derive(Debug, Args)]
pub struct BenchTasksArgs {
    /// Folder of task programs (every `*.json` in it).
    #[arg(long, default_value_os_t = paths::fixtures_dir().join("tasks"))]
    tasks: PathBuf,
    /// Only tasks whose file name contains one of these strings.
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Methods to run (`rg-dno` too; the table then compares it with DNO per task).
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [MethodArg::Unconstrained, MethodArg::Ik, MethodArg::IkReg, MethodArg::Dno])]
    methods: Vec<MethodArg>,
    #[command(flatten)]
    generation: GenerationArgs,
    /// Output folder: results.json, results.md and one folder of motions per task and method.
    /// A row already in results.json is kept and not run again when it was made by this prior
    /// file (same SHA-256) with this run's settings (RG-DNO's stage settings included), exactly
    /// as written there; a row of the same task and method made otherwise (or by a build whose
    /// report lacked one of today's settings or the prior) is run again and replaced.
    #[arg(long, short, default_value = "out/bench-tasks")]
    out: PathBuf,
}

/// One row of the results table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ResultRow {
    /// Task file stem.
    pub task: String,
    /// The run's report.
    pub report: TaskReport,
}

/// A row of `results.json` with the JSON it was read from, which is written back unchanged: read
/// into a [`ResultRow`], a row made before a setting existed takes a default for it (today's,
/// for most settings), and written back from there it would pass for a run with those settings.
struct StoredRow {
    row: ResultRow,
    json: serde_json::Value,
}

impl StoredRow {
    fn new(row: ResultRow) -> serde_json::Result<Self> {
        let json = serde_json::to_value(&row)?;
        Ok(Self { row, json })
    }

    /// The rows of a `results.json`.
    fn read(text: &str) -> serde_json::Result<Vec<Self>> {
        let rows: Vec<serde_json::Value> = serde_json::from_str(text)?;
        rows.into_iter().map(|json| Ok(Self { row: serde_json::from_value(json.clone())?, json })).collect()
    }

    /// `results.json` holding `rows`.
    fn json(rows: &[Self]) -> serde_json::Result<String> {
        serde_json::to_string_pretty(&rows.iter().map(|r| &r.json).collect::<Vec<_>>())
    }

    /// Whether the row was made by `prior` with exactly `settings`, as its JSON says: the same
    /// prior file (name and SHA-256), the same generation settings and, for a row that ran
    /// RG-DNO's stages, the same stage settings. A row written before the prior was recorded
    /// names none, so it is not taken for any prior's.
    fn made_with(&self, settings: &TaskSettings, prior: Option<&PriorIdentity>) -> serde_json::Result<bool> {
        let written = |pointer: &str, value: serde_json::Value| self.json.pointer(pointer) == Some(&value);
        let rg_dno_same = self.json.pointer("/report/rg_dno").is_none()
            || written("/report/rg_dno/config", serde_json::to_value(&settings.rg_dno)?);
        let prior_same = match prior {
            Some(prior) => written("/report/prior", serde_json::to_value(prior)?),
            None => self.json.pointer("/report/prior").is_none(),
        };
        Ok(prior_same && rg_dno_same && written("/report/config", serde_json::to_value(&settings.generation)?))
    }
}

pub fn run_tasks(args: BenchTasksArgs) -> anyhow::Result<()> {
    let device = device()?;
    let prior = load_prior(&args.generation.prior, &device)?;
    let mut files: Vec<PathBuf> = std::fs::read_dir(&args.tasks)
        .with_context(|| format!("listing {}", args.tasks.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .filter(|p| args.only.is_empty() || args.only.iter().any(|o| p.to_string_lossy().contains(o.as_str())))
        .collect();
    files.sort();
    anyhow::ensure!(!files.is_empty(), "no task files in {}", args.tasks.display());
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let json_path = args.out.join("results.json");
    let mut rows = match std::fs::read_to_string(&json_path) {
        Ok(text) => StoredRow::read(&text).with_context(|| format!("reading {}", json_path.display()))?,
        Err(_) => Vec::new(),
    };
    // RG-DNO's database, opened by the first run that retrieves and kept for the others.
    let mut database = None;
    for file in &files {
        let task = file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let program = load_program(file, &device)?;
        for &method in &args.methods {
            let method = Method::from(method);
            let settings = args.generation.settings(method)?;
            match rows.iter().position(|r| r.row.task == task && r.row.report.config.method == method) {
                Some(k) if rows[k].made_with(&settings, prior.identity.as_ref())? => continue,
                Some(k) => {
                    eprintln!(
                        "{task} / {method}: {} holds a run with other settings or another prior; running it again",
                        json_path.display()
                    );
                    rows.remove(k);
                }
                None => {}
            }
            eprintln!("{task} / {method}");
            let folder = OutputFolder::create(&args.out.join(&task).join(method.name()))?;
            let opened = match &mut database {
                _ if !retrieves(program.program(), &settings) => None,
                Some(opened) => Some(&*opened),
                None => Some(&*database.insert(OpenedDatabase::open(&settings)?)),
            };
            let report = run_with_progress(&prior, &program, &settings, opened, folder, &device)?;
            rows.push(StoredRow::new(ResultRow { task: task.clone(), report })?);
            write_atomically(&json_path, StoredRow::json(&rows)?.as_bytes())?;
            let table: Vec<ResultRow> = rows.iter().map(|r| r.row.clone()).collect();
            write_atomically(&args.out.join("results.md"), markdown(&table).as_bytes())?;
        }
    }
    rows.sort_by(|a, b| (&a.row.task, a.row.report.config.method).cmp(&(&b.row.task, b.row.report.config.method)));
    std::fs::write(&json_path, StoredRow::json(&rows)?).with_context(|| format!("writing {}", json_path.display()))?;
    let rows: Vec<ResultRow> = rows.into_iter().map(|r| r.row).collect();
    std::fs::write(args.out.join("results.md"), markdown(&rows))?;
    println!("{}", markdown(&rows));
    println!("wrote {} and {}", json_path.display(), args.out.join("results.md").display());
    Ok(())
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("–".to_owned(), |v| format!("{v:.digits$}"))
}

/// The results table: one line per task and method, then DNO's gain over unconstrained
/// sampling per task.
pub fn markdown(rows: &[ResultRow]) -> String {
    let mut by_task: BTreeMap<&str, BTreeMap<Method, &TaskReport>> = BTreeMap::new();
    for r in rows {
        by_task.entry(&r.task).or_default().insert(r.report.config.method, &r.report);
    }
    let mut out = settings_and_priors(rows);
    out.push_str(&method_rows(rows));
    out.push_str(&dno_against_unconstrained(&by_task));
    out.push_str(&rg_dno_against_dno(&by_task));
    out
}

/// The table's settings (and whether its rows mix settings) and the priors that made its rows.
fn settings_and_priors(rows: &[ResultRow]) -> String {
    let mut out = String::new();
    if let Some(first) = rows.first() {
        let c = &first.report.config;
        out.push_str(&format!(
            "Settings: {} sample(s) per task, seed {}, guidance {}, schedule {}, DNO {} steps (lr {}, ddim{}, {} restart(s), jitter guard weight {}, flight guard weight {}, ballistic guard weight {}, floor guard weight {}), IK {} steps (lr {}), IK+Reg smoothness weight {}.\n\n",
            c.samples, c.seed, c.guidance, schedule_name(c.schedule), c.dno.steps, c.dno.lr, c.dno.ddim_steps, c.dno.restarts, c.guards.jitter, c.guards.flight, c.guards.ballistic, c.guards.floor, c.direct.steps, c.direct.lr, c.direct.smoothness_weight
        ));
        if rows.iter().any(|r| GenerationConfig { method: c.method, ..r.report.config.clone() } != *c) {
            out.push_str("**The rows were made with different settings** (rows kept from earlier runs); each row's are in results.json.\n\n");
        }
        let priors: BTreeSet<String> = rows
            .iter()
            .map(|r| {
                r.report.prior.as_ref().map_or_else(
                    || "not recorded".to_owned(),
                    |p| format!("`{}` (SHA-256 {})", p.file, p.sha256.get(..12).unwrap_or(&p.sha256)),
                )
            })
            .collect();
        let priors: Vec<String> = priors.into_iter().collect();
        match priors.as_slice() {
            [one] => out.push_str(&format!("Prior: {one}.\n\n")),
            many => out.push_str(&format!("**The rows were made by different priors**: {}.\n\n", many.join(", "))),
        }
    }
    out
}

/// The schedule as the command line names it.
fn schedule_name(schedule: Schedule) -> &'static str {
    match schedule {
        Schedule::Paper => "paper (every stage runs its budget)",
        Schedule::UntilMet => "until-met (each stage ends once its work is done)",
    }
}

/// One line per task and method.
fn method_rows(rows: &[ResultRow]) -> String {
    let mut out = String::new();
    out.push_str(
        "Every figure is measured on the written joints, after the kinematic refinement and the foot clean-up; \
         \"all met\", \"max scene penetration\" and \"foot skate\" give the network's motion → the written one. \
         The same figures for held-out capture of each skill are in the prior's report (`mogen report prior`).\n\n",
    );
    out.push_str("| task | method | constraint error | all met | max scene penetration (m) | under floor (m) | leg alternations/s | toe flicker | mean acc (m/frame²) | max acc (m/frame²) | foot skate | lower toe (m) | floating (longest flight, s) | steps as footfalls (leg alternations) (target) / success | the skill named: detected | time (s) |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let p = &r.report;
        let steps = p
            .steps
            .as_ref()
            .map_or("–".to_owned(), |s| format!("{} ({}) / {:.2}", s.counts_text(), s.target, s.success_rate));
        let before = &p.cleanup.before;
        let (skate, met, penetration) = if p.cleanup.enabled || p.cleanup.refine_enabled {
            (
                format!("{:.3} → {:.3}", before.motion.foot_skate_ratio, p.motion.foot_skate_ratio),
                format!("{:.0}% → {:.0}%", 100.0 * before.success_rate, 100.0 * p.success_rate),
                format!("{} → {}", fmt_opt(before.max_scene_penetration_m, 3), fmt_opt(p.max_scene_penetration_m, 3)),
            )
        } else {
            (
                format!("{:.3}", p.motion.foot_skate_ratio),
                format!("{:.0}%", 100.0 * p.success_rate),
                fmt_opt(p.max_scene_penetration_m, 3),
            )
        };
        let skill = p.skill.as_ref().map_or("–".to_owned(), |s| format!("{}: {}", s.family, s.passed_text()));
        // With --retry-unmet: how many samples kept a later attempt.
        let met = match &p.attempt {
            Some(kept) => format!("{met} ({} of {} retried)", kept.iter().filter(|&&k| k > 0).count(), kept.len()),
            None => met,
        };
        out.push_str(&format!(
            "| {} | {} | {:.6} | {met} | {penetration} | {:.3} | {:.2} | {:.3} | {:.4} | {:.3} | {skate} | {:.3} | {:.0}% ({:.2}) | {steps} | {skill} | {:.1} |\n",
            r.task,
            p.config.method,
            p.constraint_error,
            p.motion.max_under_floor_m,
            p.motion.pace_steps_per_s,
            p.motion.toe_flicker,
            p.motion.mean_acceleration,
            p.motion.max_acceleration,
            p.motion.stance_toe_height_m,
            100.0 * p.motion.floating_share,
            p.motion.longest_flight_s,
            p.seconds
        ));
    }
    out
}

/// DNO's gain over unconstrained sampling, per task.
fn dno_against_unconstrained(by_task: &BTreeMap<&str, BTreeMap<Method, &TaskReport>>) -> String {
    let mut out = String::new();
    out.push_str("\nDNO against unconstrained sampling (error ratio: unconstrained / DNO; acceleration ratio: DNO / unconstrained):\n\n");
    out.push_str("| task | error ratio | acceleration ratio |\n|---|---|---|\n");
    for (task, methods) in by_task {
        if let (Some(u), Some(d)) = (methods.get(&Method::Unconstrained), methods.get(&Method::Dno)) {
            let ratio = if d.constraint_error > 0.0 {
                format!("{:.1}", u.constraint_error / d.constraint_error)
            } else {
                "∞".into()
            };
            out.push_str(&format!(
                "| {task} | {ratio} | {:.2} |\n",
                d.motion.max_acceleration / u.motion.max_acceleration.max(1e-12)
            ));
        }
    }
    out
}

/// RG-DNO against DNO, per task that has both.
fn rg_dno_against_dno(by_task: &BTreeMap<&str, BTreeMap<Method, &TaskReport>>) -> String {
    let mut out = String::new();
    let pairs: Vec<_> =
        by_task.iter().filter_map(|(task, m)| Some((task, m.get(&Method::Dno)?, m.get(&Method::RgDno)?))).collect();
    if !pairs.is_empty() {
        out.push_str(
            "\nRG-DNO against DNO (same seeds; errors after the refinement and the clean-up, the network's in brackets):\n\n",
        );
        out.push_str(
            "| task | DNO error | RG-DNO error | lower | all met DNO → RG-DNO | max penetration (m) DNO → RG-DNO | max acc DNO → RG-DNO | steps DNO → RG-DNO | retrieved | time DNO → RG-DNO (s) |\n",
        );
        out.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
        for (task, d, r) in pairs {
            let steps = |p: &TaskReport| p.steps.as_ref().map_or("–".to_owned(), |s| s.counts_text());
            let retrieved = r.rg_dno.as_ref().and_then(|rg| Some((rg, rg.retrieved.first()?))).map_or_else(
                || r.fallback.clone().unwrap_or_default(),
                |(rg, first)| match rg.kept_motions().as_slice() {
                    [] | [(0, _)] => first.source.to_string(),
                    kept => {
                        let takes = kept
                            .iter()
                            .filter_map(|&(m, n)| Some(format!("{} ×{n}", rg.retrieved.get(m)?.source.clip)));
                        format!("{}; samples kept {}", first.source, takes.collect::<Vec<_>>().join(", "))
                    }
                },
            );
            out.push_str(&format!(
                "| {task} | {:.6} ({:.6}) | {:.6} ({:.6}) | {} | {:.0}% → {:.0}% | {} → {} | {:.3} → {:.3} | {} → {} | {retrieved} | {:.0} → {:.0} |\n",
                d.constraint_error,
                d.cleanup.before.constraint_error,
                r.constraint_error,
                r.cleanup.before.constraint_error,
                if r.constraint_error < d.constraint_error { "yes" } else { "no" },
                100.0 * d.success_rate,
                100.0 * r.success_rate,
                fmt_opt(d.max_scene_penetration_m, 3),
                fmt_opt(r.max_scene_penetration_m, 3),
                d.motion.max_acceleration,
                r.motion.max_acceleration,
                steps(d),
                steps(r),
                d.seconds,
                r.seconds
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use motion_core::generation::objective::Guards;
    use motion_core::generation::rgdno::candidates::RetrievalSource;
    use motion_core::generation::rgdno::config::RgDnoConfig;
    use motion_core::pipeline::ExportOptions;

    use super::*;

    /// Today's settings for `config`, RG-DNO's stages at their defaults.
    fn settings(config: &GenerationConfig) -> TaskSettings {
        TaskSettings {
            generation: config.clone(),
            rg_dno: RgDnoConfig::default(),
            database: RetrievalSource::from_path("corpus.safetensors.gz"),
            retry_unmet: 0,
            exports: ExportOptions::default(),
        }
    }

    fn prior(name: &str) -> PriorIdentity {
        PriorIdentity::of(std::path::Path::new(name), name.as_bytes())
    }

    #[test]
    fn a_stored_row_is_reused_only_with_the_prior_and_settings_it_was_written_with() {
        // A stored Table 6 whose JSON has no floor-guard setting (read as weight 0) and names no
        // prior: not a run with today's settings, nor with the same settings and the guard at 0,
        // since its JSON lacks the setting, nor any prior's.
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../fixtures/results/session34-table6-n4/results.json");
        let rows = StoredRow::read(&std::fs::read_to_string(path).unwrap()).unwrap();
        let old = &rows[0];
        assert_eq!(old.row.report.config.guards.floor, 0.0);
        assert!(old.row.report.prior.is_none());
        assert!(!old.made_with(&settings(&old.row.report.config), None).unwrap());
        let mut today = old.row.report.config.clone();
        today.guards = Guards::DEFAULT;
        assert!(!old.made_with(&settings(&today), None).unwrap());
        // Written back unchanged: still without the floor guard.
        let again = StoredRow::read(&StoredRow::json(&rows).unwrap()).unwrap();
        assert_eq!(again.len(), rows.len());
        assert!(again[0].json.pointer("/report/config/guards/floor").is_none());
        // The same run made by today's build with prior `a` is reused, and only with its own
        // settings and prior.
        let mut row = old.row.clone();
        row.report.config = today.clone();
        row.report.prior = Some(prior("a"));
        let fresh = StoredRow::new(row).unwrap();
        assert!(fresh.made_with(&settings(&today), Some(&prior("a"))).unwrap());
        assert!(!fresh.made_with(&settings(&today), Some(&prior("b"))).unwrap());
        assert!(!fresh.made_with(&settings(&today), None).unwrap());
        today.seed += 1;
        assert!(!fresh.made_with(&settings(&today), Some(&prior("a"))).unwrap());

        // An RG-DNO row also needs RG-DNO's stage settings to be this run's.
        let old = rows.iter().find(|r| r.row.report.rg_dno.is_some()).unwrap();
        let mut row = old.row.clone();
        row.report.config.guards = Guards::DEFAULT;
        row.report.prior = Some(prior("a"));
        if let Some(rg) = row.report.rg_dno.as_mut() {
            rg.config = RgDnoConfig::default();
        }
        let fresh = StoredRow::new(row.clone()).unwrap();
        let same = settings(&row.report.config);
        assert!(fresh.made_with(&same, Some(&prior("a"))).unwrap());
        let fewer_steps = TaskSettings { rg_dno: RgDnoConfig::default().scaled_to(250), ..same };
        assert!(!fresh.made_with(&fewer_steps, Some(&prior("a"))).unwrap());
    }

    /// The table names the prior of its rows and says when its rows were made with other
    /// settings or by other priors than the first row's.
    #[test]
    fn the_table_says_which_prior_and_whether_its_rows_mix_settings() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../fixtures/results/session34-table6-n4/results.json");
        let mut rows: Vec<ResultRow> =
            StoredRow::read(&std::fs::read_to_string(path).unwrap()).unwrap().into_iter().map(|r| r.row).collect();
        let table = markdown(&rows);
        assert!(table.contains("Prior: not recorded.") && !table.contains("different"), "{table}");
        for row in &mut rows {
            row.report.prior = Some(prior("a"));
        }
        let table = markdown(&rows);
        assert!(table.contains(&format!("Prior: `a` (SHA-256 {})", &prior("a").sha256[..12])), "{table}");
        rows[1].report.prior = Some(prior("b"));
        rows[2].report.config.seed += 1;
        let table = markdown(&rows);
        assert!(
            table.contains("made by different priors") && table.contains("made with different settings"),
            "{table}"
        );
    }
}
