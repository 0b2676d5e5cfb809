//! A skill family's detector (`corpus::family::Family::detect`, the one `mogen report prior`
//! judges samples with) applied to written motions: for each `joints.npy` given (`[frames, 22, 3]`
//! or `[samples, frames, 22, 3]`, metres, 20 fps), one line per motion with pass or fail, then the
//! count. The rare-skill suite's results (`fixtures/results/issue60-*`) are judged with it.
//!
//! Usage: `cargo run --release --example detect_skill -p motion-core -- FAMILY JOINTS.npy...`,
//! e.g. `crawl out/bench/skill_crawl_under_table/rg-dno/sample_*/joints.npy`; FAMILY is a name
//! of `Family::ALL` ("crawl", "sideways walk", "hop on one foot", ...).
use std::error::Error;
use std::path::Path;

use motion_core::corpus::family::Family;
use motion_core::export::read_joints_npy;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((family, files)) = args.split_first().filter(|(_, files)| !files.is_empty()) else {
        return Err("usage: detect_skill FAMILY JOINTS.npy...".into());
    };
    let family = Family::from_name(family)?;
    let detector = family.detector();
    let (mut passed, mut motions) = (0, 0);
    for file in files {
        for (k, poses) in read_joints_npy(Path::new(file))?.iter().enumerate() {
            let pass = family.detect(poses);
            println!("{file} [{k}]: {}", if pass { "passes" } else { "fails" });
            passed += usize::from(pass);
            motions += 1;
        }
    }
    println!("{}: {passed} of {motions} motions pass ({detector})", family.name());
    Ok(())
}
