//! A skill family's detector (`corpus::family::Family::detect`) over every window of a corpus
//! file: per family of the windows themselves (`Family::of`, "none" for windows of no family),
//! how many pass, and each window that passes or fails from a take whose description holds a
//! given word. The thresholds of a new detector are measured with it (the carry's:
//! `fixtures/results/issue60-skill-retry/`).
//!
//! Usage: `cargo run --release --example detector_on_corpus -p motion-core -- FAMILY [WORD]
//! [CORPUS]`, e.g. `carry box` (CORPUS: `fixtures/corpus/corpus.safetensors.gz`).
use std::collections::BTreeMap;
use std::error::Error;
use std::path::Path;

use motion_core::corpus::family::Family;
use motion_core::corpus::file::load;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let family = Family::from_name(args.first().ok_or("usage: detector_on_corpus FAMILY [WORD] [CORPUS]")?)?;
    let word = args.get(1).map(|w| w.to_lowercase());
    let path = args.get(2).map_or("fixtures/corpus/corpus.safetensors.gz", String::as_str);
    let corpus = load(Path::new(path))?;
    let mut counts: BTreeMap<&str, (usize, usize)> = BTreeMap::new();
    for window in &corpus.windows {
        let clip = &corpus.clips[window.clip];
        let poses = corpus.window_joints(window);
        let own = Family::of(poses, &window.tags, &clip.description).map_or("none", Family::name);
        let pass = family.detect(poses);
        let count = counts.entry(own).or_default();
        *count = (count.0 + 1, count.1 + usize::from(pass));
        if word.as_ref().is_some_and(|w| clip.description.to_lowercase().contains(w.as_str())) {
            let verdict = if pass { "passes" } else { "fails" };
            println!("{verdict}: {} frames {}.. ({own}): {}", clip.name, window.start, clip.description);
        }
    }
    println!("{} ({}) over {path}:", family.name(), family.detector());
    for (own, (windows, passed)) in counts {
        println!("  {own:18} {passed:5} of {windows:5} windows pass ({:.1} %)", 100.0 * passed as f64 / windows as f64);
    }
    Ok(())
}
