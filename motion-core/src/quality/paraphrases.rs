//! Held-out paraphrases (issue 40: "prompts never seen in training go the way their words
//! say"): prompts written for a skill family before they were ever encoded or sampled, each
//! sampled freely ([`Prior::sample`]: restated, then heard as its nearest training caption)
//! and judged by its family's action detector ([`Family::detect`]).
//!
//! File format (`fixtures/model/held_out_paraphrases.tsv`): one `family<TAB>prompt` per line,
//! the family by its [`Family::name`]; blank lines and lines starting with `#` are skipped.

use std::path::Path;

use serde::Serialize;

use super::families::detected_share;
use super::sampling::{joints_of, Denoising};
use crate::corpus::family::Family;
use crate::files::{read_text, FileError};
use crate::limits::PROMPT_LIST_FILE_BYTES;
use crate::prior::{Prior, PriorError};

/// One paraphrase of a family.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Paraphrase {
    /// The family its words ask for.
    pub family: Family,
    /// The prompt.
    pub prompt: String,
}

/// Reads a paraphrase file ([module doc](self)). Errors name the file and the line.
pub fn read_paraphrases(path: &Path) -> Result<Vec<Paraphrase>, FileError> {
    let text = read_text(path, &PROMPT_LIST_FILE_BYTES)?;
    parse_paraphrases(&text).map_err(|message| FileError::format(path, message))
}

fn parse_paraphrases(text: &str) -> Result<Vec<Paraphrase>, String> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|(i, line)| {
            let at = |message: String| format!("line {}: {message}", i + 1);
            let (name, prompt) = line.split_once('\t').ok_or_else(|| at("expected `family<TAB>prompt`".to_owned()))?;
            let family = Family::from_name(name.trim()).map_err(at)?;
            let prompt = prompt.trim();
            if prompt.is_empty() {
                return Err(at("the prompt is empty".to_owned()));
            }
            Ok(Paraphrase { family, prompt: prompt.to_owned() })
        })
        .collect()
}

/// How one paraphrase fared.
#[derive(Debug, Clone, Serialize)]
pub struct ParaphraseOutcome {
    /// The paraphrase.
    pub paraphrase: Paraphrase,
    /// The prompt as restated in the training captions' verbs (the prompt when unchanged).
    pub restated: String,
    /// The training caption it was heard as, and the cosine similarity to it (`None` without a
    /// caption bank).
    pub heard_as: Option<(String, f32)>,
    /// Samples drawn.
    pub samples: usize,
    /// Share of them passing the family's detector (`None`: the family has none).
    pub detected: Option<f64>,
}

/// `samples` free samples of each paraphrase (paraphrase i's noise from seed + 100·i) through
/// its family's detector, on the network's output.
pub fn paraphrase_report(
    prior: &Prior,
    paraphrases: &[Paraphrase],
    samples: usize,
    frames: usize,
    denoising: Denoising,
) -> Result<Vec<ParaphraseOutcome>, PriorError> {
    let tensor = |e: candle_core::Error| PriorError::Compute { what: "the paraphrase report", message: e.to_string() };
    let device = prior.mean_std.mean().device().clone();
    paraphrases
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let request = denoising.request(&p.prompt, frames, samples, 100 * i as u64);
            let motions = joints_of(prior, &prior.sample(&request, &device)?).map_err(tensor)?;
            let detected = detected_share(p.family, &motions);
            let heard_as = prior.nearest_caption(&p.prompt).map_err(tensor)?.map(|n| (n.caption, n.similarity));
            Ok(ParaphraseOutcome {
                paraphrase: p.clone(),
                restated: prior.restate(&p.prompt).text,
                heard_as,
                samples,
                detected,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_paraphrase_file_names_families_and_prompts_and_its_errors_say_which_line() {
        let parsed =
            parse_paraphrases("# note\n\nturn left\tsomeone veers left \nsit down\tsomeone takes a seat\n").unwrap();
        assert_eq!(
            parsed,
            [
                Paraphrase { family: Family::TurnLeft, prompt: "someone veers left".into() },
                Paraphrase { family: Family::SitDown, prompt: "someone takes a seat".into() },
            ]
        );
        let err = parse_paraphrases("walk\tok\nskate\tsomeone glides").unwrap_err();
        assert!(err.starts_with("line 2: unknown family \"skate\""), "{err}");
        assert!(parse_paraphrases("walk someone walks").unwrap_err().contains("family<TAB>prompt"));
        assert!(parse_paraphrases("walk\t  ").unwrap_err().contains("empty"));
    }
}
