//! Draws catalog clips as they are imported, to look at them: one PNG per clip, its 20 fps
//! poses (world coordinates, as `pose_at` gives them) cut into rows of `SECONDS` each, with
//! 8 stick figures per row and the shared top view of the pelvis and feet.
//!
//! Usage: `cargo run --release --example render_catalog_clips -p motion-core -- CATALOG OUT_DIR [FILTER] [SECONDS]`
//! (`FILTER`: only clips whose file path contains it; `SECONDS`: row length, default 3).
use std::error::Error;
use std::path::Path;

use motion_core::database::catalog::Catalog;
use motion_core::import::resample;
use motion_core::render::{motion_strip, StripRow};
use motion_core::skeleton::FPS;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (catalog, out) = match args.as_slice() {
        [_, catalog, out, ..] => (Path::new(catalog), Path::new(out)),
        _ => return Err("usage: render_catalog_clips CATALOG OUT_DIR [FILTER] [SECONDS]".into()),
    };
    let filter = args.get(3).map(String::as_str).unwrap_or("");
    let seconds: f64 = args.get(4).map(|s| s.parse()).transpose()?.unwrap_or(3.0);
    let mut catalog = Catalog::read(catalog)?;
    catalog.clips.retain(|c| c.file.to_string_lossy().contains(filter));
    let (clips, warnings) = catalog.load()?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    std::fs::create_dir_all(out)?;
    for source in clips {
        let poses = resample(source.clip.as_ref(), 1.0, None);
        let per_row = ((seconds * FPS) as usize).max(2);
        let rows: Vec<StripRow<'_>> = poses
            .chunks(per_row)
            .enumerate()
            .map(|(i, chunk)| StripRow {
                label: format!("{:.1}-{:.1} s", i as f64 * seconds, i as f64 * seconds + chunk.len() as f64 / FPS),
                poses: chunk,
            })
            .collect();
        let path = out.join(format!("{}.png", source.name));
        motion_strip(&rows, 8, &[], &[], &format!("{}: {}", source.name, source.label), &path)?;
        println!("{}", path.display());
    }
    Ok(())
}
