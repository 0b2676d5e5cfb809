//! Stick-figure strips: one row per motion, a side view (z to the right, y up) of evenly
//! spaced frames, each panel centred on the pelvis; left limbs blue, right limbs red.

use std::path::Path;

use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Stroke, Transform};

use super::font::draw_text;
use super::{save_png, RenderError};
use crate::skeleton::{bones, Pose};

/// One row of a strip.
pub struct StripRow<'a> {
    /// Text drawn above the row.
    pub label: String,
    /// The motion, 20 fps.
    pub poses: &'a [Pose],
}

const PANEL_PX: f32 = 150.0;
const LABEL_PX: f32 = 18.0;
/// Metres shown across a panel's height.
const PANEL_M: f32 = 2.2;

/// Draws `panels` evenly spaced frames of every row to a PNG.
pub fn motion_strip(rows: &[StripRow<'_>], panels: usize, path: &Path) -> Result<(), RenderError> {
    let panels = panels.max(1);
    if rows.is_empty() || rows.iter().any(|r| r.poses.is_empty()) {
        return Err(RenderError::Empty("no motion to draw".into()));
    }
    let (w, h) = (PANEL_PX * panels as f32, (PANEL_PX + LABEL_PX) * rows.len() as f32);
    let mut pixmap = Pixmap::new(w as u32, h as u32).ok_or_else(|| RenderError::Empty(format!("{w}x{h} pixels")))?;
    pixmap.fill(Color::WHITE);
    let scale = PANEL_PX / PANEL_M;
    for (r, row) in rows.iter().enumerate() {
        let top = r as f32 * (PANEL_PX + LABEL_PX);
        draw_text(&mut pixmap, &row.label, 4.0, top + 4.0, 1.5, Color::BLACK);
        for p in 0..panels {
            let t = if panels == 1 { 0 } else { p * (row.poses.len() - 1) / (panels - 1) };
            let pose = &row.poses[t];
            let (cx, ground) = (p as f32 * PANEL_PX + PANEL_PX / 2.0, top + LABEL_PX + PANEL_PX - 10.0);
            let to_px = |v: glam::DVec3| (cx + (v.z - pose[0].z) as f32 * scale, ground - v.y as f32 * scale);
            line(
                &mut pixmap,
                (p as f32 * PANEL_PX + 5.0, ground),
                ((p + 1) as f32 * PANEL_PX - 5.0, ground),
                Color::from_rgba8(170, 170, 170, 255),
                1.0,
            );
            draw_text(
                &mut pixmap,
                &format!("{:.1}S", t as f64 / crate::skeleton::FPS),
                p as f32 * PANEL_PX + 4.0,
                ground + 2.0,
                1.0,
                Color::from_rgba8(120, 120, 120, 255),
            );
            for (parent, child) in bones() {
                let color = match child.name() {
                    n if n.starts_with("left_") => Color::from_rgba8(40, 80, 220, 255),
                    n if n.starts_with("right_") => Color::from_rgba8(220, 50, 40, 255),
                    _ => Color::from_rgba8(60, 60, 60, 255),
                };
                line(&mut pixmap, to_px(pose[parent.index()]), to_px(pose[child.index()]), color, 2.5);
            }
        }
    }
    save_png(&pixmap, path)
}

pub(super) fn line(pixmap: &mut Pixmap, a: (f32, f32), b: (f32, f32), color: Color, width: f32) {
    let mut pb = PathBuilder::new();
    pb.move_to(a.0, a.1);
    pb.line_to(b.0, b.1);
    if let Some(path) = pb.finish() {
        let mut paint = Paint::default();
        paint.set_color(color);
        paint.anti_alias = true;
        pixmap.stroke_path(&path, &paint, &Stroke { width, ..Stroke::default() }, Transform::identity(), None);
    }
}
