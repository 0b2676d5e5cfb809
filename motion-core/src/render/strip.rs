//! Motions in world coordinates: one side view per motion (z forward to the right, y up) with
//! stick figures at evenly spaced frames drawn where they are, so travel shows, and one shared
//! top view (z to the right, x = the character's left up) with every motion's pelvis and foot
//! trajectories. Both views share one metric scale, carry metre ticks and draw the task's scene
//! (barriers, hurdles, gaps, walls, boxes). Left limbs blue, right limbs red, mid-line in the
//! motion's own colour; later frames darker.

use std::path::Path;

use glam::DVec3;
use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};

use super::font::draw_text;
use super::{save_png, RenderError};
use crate::program::{Gap, Hurdle, InsideBox, OverheadBarrier, Primitive, Wall};
use crate::skeleton::{bones, Joint, Pose, FPS};

/// One motion of a strip.
pub struct StripRow<'a> {
    /// Text drawn above its side view.
    pub label: String,
    /// The motion, 20 fps, world coordinates.
    pub poses: &'a [Pose],
}

/// Distinct colours of the motions (and their trajectories in the top view).
const PALETTE: [(u8, u8, u8); 8] = [
    (0, 114, 178),
    (213, 94, 0),
    (0, 158, 115),
    (204, 121, 167),
    (86, 180, 233),
    (230, 159, 0),
    (120, 120, 120),
    (0, 0, 0),
];
const MARGIN_PX: f32 = 40.0;
const LABEL_PX: f32 = 16.0;
/// Height shown in a side view, m (more when a motion reaches higher).
const SIDE_HEIGHT_M: f64 = 2.2;
/// Widest picture, px.
const MAX_WIDTH_PX: f64 = 1800.0;
/// Pixels per metre at most.
const MAX_SCALE: f64 = 160.0;

fn colour((r, g, b): (u8, u8, u8), alpha: u8) -> Color {
    Color::from_rgba8(r, g, b, alpha)
}

/// Draws `figures` evenly spaced frames of every motion in world coordinates, with the scene
/// primitives, to a PNG at `path`.
pub fn motion_strip(
    rows: &[StripRow<'_>],
    figures: usize,
    scene: &[Primitive],
    title: &str,
    path: &Path,
) -> Result<(), RenderError> {
    let figures = figures.max(1);
    if rows.is_empty() || rows.iter().any(|r| r.poses.is_empty()) {
        return Err(RenderError::Empty("no motion to draw".into()));
    }
    let points = || rows.iter().flat_map(|r| r.poses.iter().flatten());
    let finite = |v: &DVec3| v.is_finite();
    if !points().all(finite) {
        return Err(RenderError::Empty("the motion has non-finite joint positions".into()));
    }
    let mut z =
        (points().map(|v| v.z).fold(f64::INFINITY, f64::min), points().map(|v| v.z).fold(f64::NEG_INFINITY, f64::max));
    let mut x =
        (points().map(|v| v.x).fold(f64::INFINITY, f64::min), points().map(|v| v.x).fold(f64::NEG_INFINITY, f64::max));
    for p in scene {
        if let Some([lo, hi]) = scene_z_range(p) {
            z = (z.0.min(lo), z.1.max(hi));
        }
        if let Some([lo, hi]) = scene_x_range(p) {
            x = (x.0.min(lo), x.1.max(hi));
        }
    }
    let (z, x) = ((z.0 - 0.3, z.1 + 0.3), (x.0.min(-0.5) - 0.2, x.1.max(0.5) + 0.2));
    let top_y = points().map(|v| v.y).fold(SIDE_HEIGHT_M, f64::max) + 0.1;
    let scale = (MAX_WIDTH_PX / (z.1 - z.0)).min(MAX_SCALE);
    let width = (z.1 - z.0) * scale + 2.0 * MARGIN_PX as f64;
    let side_h = top_y * scale + LABEL_PX as f64 + 32.0;
    let top_h = (x.1 - x.0) * scale + LABEL_PX as f64 + 32.0;
    let height = LABEL_PX as f64 + 8.0 + side_h * rows.len() as f64 + top_h + 8.0;
    let mut pixmap = Pixmap::new(width as u32, height as u32)
        .ok_or_else(|| RenderError::Empty(format!("{width:.0}x{height:.0} pixels")))?;
    pixmap.fill(Color::WHITE);
    draw_text(&mut pixmap, &title.to_uppercase(), 4.0, 4.0, 1.5, Color::BLACK);
    let px_z = |v: f64| (MARGIN_PX as f64 + (v - z.0) * scale) as f32;
    let grey = Color::from_rgba8(150, 150, 150, 255);
    let obstacle = Color::from_rgba8(120, 120, 120, 90);

    // Side views.
    for (r, row) in rows.iter().enumerate() {
        let rgb = PALETTE[r % PALETTE.len()];
        let top = (LABEL_PX as f64 + 8.0 + r as f64 * side_h) as f32;
        let ground = top + LABEL_PX + (top_y * scale) as f32;
        let px = |v: DVec3| (px_z(v.z), ground - (v.y * scale) as f32);
        draw_text(
            &mut pixmap,
            &format!("{} - SIDE VIEW", row.label).to_uppercase(),
            4.0,
            top + 2.0,
            1.2,
            colour(rgb, 255),
        );
        for p in scene {
            if let Some((lo, hi, [z0, z1])) = side_box(p, top_y) {
                fill(
                    &mut pixmap,
                    (px_z(z0), ground - (hi * scale) as f32),
                    (px_z(z1), ground - (lo * scale) as f32),
                    obstacle,
                );
            }
            if let Primitive::Wall(Wall { point_m, normal, .. }) = p {
                if normal[2].abs() > 0.9 {
                    line(&mut pixmap, (px_z(point_m[2]), ground), (px_z(point_m[2]), top + LABEL_PX), grey, 3.0);
                }
            }
        }
        axis(&mut pixmap, z, scale, ground, &px_z, "Z FORWARD (M)");
        for (k, h) in (0..=(top_y as usize)).map(|k| (k, k as f64)) {
            let y = ground - (h * scale) as f32;
            line(&mut pixmap, (MARGIN_PX - 6.0, y), (MARGIN_PX, y), grey, 1.0);
            draw_text(&mut pixmap, &format!("{k}"), MARGIN_PX - 16.0, y - 4.0, 1.0, grey);
        }
        let pelvis: Vec<(f32, f32)> = row.poses.iter().map(|p| px(p[Joint::Pelvis.index()])).collect();
        polyline(&mut pixmap, &pelvis, colour(rgb, 160), 1.0);
        for f in 0..figures {
            let t = if figures == 1 { 0 } else { f * (row.poses.len() - 1) / (figures - 1) };
            let alpha = (90.0 + 165.0 * f as f32 / figures.max(2).saturating_sub(1) as f32) as u8;
            let pose = &row.poses[t];
            for (parent, child) in bones() {
                let c = match child.name() {
                    n if n.starts_with("left_") => colour((40, 80, 220), alpha),
                    n if n.starts_with("right_") => colour((220, 50, 40), alpha),
                    _ => colour(rgb, alpha),
                };
                line(&mut pixmap, px(pose[parent.index()]), px(pose[child.index()]), c, 2.0);
            }
            let head = px(pose[Joint::Head.index()]);
            draw_text(&mut pixmap, &format!("{:.1}S", t as f64 / FPS), head.0 - 8.0, head.1 - 16.0, 1.0, grey);
        }
    }

    // Top view.
    let top = (LABEL_PX as f64 + 8.0 + rows.len() as f64 * side_h) as f32;
    let bottom = top + LABEL_PX + ((x.1 - x.0) * scale) as f32;
    let px_x = |v: f64| bottom - ((v - x.0) * scale) as f32;
    draw_text(
        &mut pixmap,
        "TOP VIEW: PELVIS (THICK) AND FEET (THIN) OF EVERY MOTION",
        4.0,
        top + 2.0,
        1.2,
        Color::BLACK,
    );
    for p in scene {
        for ([z0, z1], [x0, x1]) in top_boxes(p, z, x) {
            fill(&mut pixmap, (px_z(z0), px_x(x1)), (px_z(z1), px_x(x0)), obstacle);
        }
    }
    axis(&mut pixmap, z, scale, bottom, &px_z, "Z FORWARD (M)");
    let mut k = x.0.ceil();
    while k <= x.1 {
        let y = px_x(k);
        line(&mut pixmap, (MARGIN_PX - 6.0, y), (MARGIN_PX, y), grey, 1.0);
        draw_text(&mut pixmap, &format!("{}", k.round() as i64), MARGIN_PX - 22.0, y - 4.0, 1.0, grey);
        k += 1.0;
    }
    draw_text(&mut pixmap, "X LEFT", 2.0, top + LABEL_PX, 1.0, grey);
    for (r, row) in rows.iter().enumerate() {
        let rgb = PALETTE[r % PALETTE.len()];
        for (joint, width) in [(Joint::Pelvis, 2.5), (Joint::LeftFoot, 1.0), (Joint::RightFoot, 1.0)] {
            let track: Vec<(f32, f32)> =
                row.poses.iter().map(|p| (px_z(p[joint.index()].z), px_x(p[joint.index()].x))).collect();
            polyline(&mut pixmap, &track, colour(rgb, 220), width);
        }
    }
    save_png(&pixmap, path)
}

/// Metre ticks along z at the baseline `y_px`, labelled, with the axis name at the right.
fn axis(pixmap: &mut Pixmap, z: (f64, f64), scale: f64, y_px: f32, px_z: &dyn Fn(f64) -> f32, name: &str) {
    let grey = Color::from_rgba8(150, 150, 150, 255);
    line(pixmap, (px_z(z.0), y_px), (px_z(z.1), y_px), grey, 1.0);
    let step = if scale < 40.0 { 2.0 } else { 1.0 };
    let mut k = (z.0 / step).ceil() * step;
    while k <= z.1 {
        line(pixmap, (px_z(k), y_px), (px_z(k), y_px + 6.0), grey, 1.0);
        draw_text(pixmap, &format!("{}", k.round() as i64), px_z(k) - 3.0, y_px + 8.0, 1.0, grey);
        if scale >= 80.0 && k + 0.5 <= z.1 {
            line(pixmap, (px_z(k + 0.5), y_px), (px_z(k + 0.5), y_px + 3.0), grey, 1.0);
        }
        k += step;
    }
    draw_text(pixmap, name, px_z(z.1) - 90.0, y_px + 18.0, 1.0, grey);
}

/// z extent of a primitive, m, when it has one.
fn scene_z_range(p: &Primitive) -> Option<[f64; 2]> {
    match p {
        Primitive::OverheadBarrier(OverheadBarrier { z_range_m, .. }) | Primitive::Hurdle(Hurdle { z_range_m, .. }) => {
            Some(*z_range_m)
        }
        Primitive::Gap(Gap { z_range_m, .. }) | Primitive::InsideBox(InsideBox { z_range_m, .. }) => *z_range_m,
        Primitive::Wall(Wall { point_m, normal, .. }) if normal[2].abs() > 0.9 => Some([point_m[2]; 2]),
        _ => None,
    }
}

/// x extent of a primitive, m, when it has one.
fn scene_x_range(p: &Primitive) -> Option<[f64; 2]> {
    match p {
        Primitive::Gap(Gap { centre_x_m, width_m, .. }) => Some([centre_x_m - width_m, centre_x_m + width_m]),
        Primitive::InsideBox(InsideBox { x_range_m, .. }) => *x_range_m,
        Primitive::Wall(Wall { point_m, normal, .. }) if normal[0].abs() > 0.9 => Some([point_m[0]; 2]),
        _ => None,
    }
}

/// A primitive's side-view rectangle: (y low, y high, z range), m.
fn side_box(p: &Primitive, top_y: f64) -> Option<(f64, f64, [f64; 2])> {
    match p {
        Primitive::OverheadBarrier(b) => Some((b.underside_height_m, top_y, b.z_range_m)),
        Primitive::Hurdle(h) => Some((0.0, h.height_m, h.z_range_m)),
        _ => None,
    }
}

/// A primitive's solid parts in the top view, each ([z0, z1], [x0, x1]), m: both walls of a
/// gap, the outside of a box's x range, a wall's slab 5 cm thick.
fn top_boxes(p: &Primitive, z: (f64, f64), x: (f64, f64)) -> Vec<([f64; 2], [f64; 2])> {
    match p {
        Primitive::Gap(g) => {
            let zr = g.z_range_m.unwrap_or([z.0, z.1]);
            let half = g.width_m / 2.0;
            vec![(zr, [g.centre_x_m + half, x.1]), (zr, [x.0, g.centre_x_m - half])]
        }
        Primitive::Wall(Wall { point_m, normal, .. }) if normal[0].abs() > 0.9 => {
            let behind =
                if normal[0] > 0.0 { [point_m[0] - 0.05, point_m[0]] } else { [point_m[0], point_m[0] + 0.05] };
            vec![([z.0, z.1], behind)]
        }
        Primitive::InsideBox(InsideBox { x_range_m: Some([lo, hi]), z_range_m, .. }) => {
            let zr = z_range_m.unwrap_or([z.0, z.1]);
            vec![(zr, [x.0, *lo]), (zr, [*hi, x.1])]
        }
        _ => Vec::new(),
    }
}

fn fill(pixmap: &mut Pixmap, a: (f32, f32), b: (f32, f32), color: Color) {
    if let Some(rect) = Rect::from_ltrb(a.0.min(b.0), a.1.min(b.1), a.0.max(b.0).max(a.0.min(b.0) + 2.0), a.1.max(b.1))
    {
        let mut paint = Paint::default();
        paint.set_color(color);
        // tiny-skia's anti-aliased rectangle fill asserts on rectangles under a pixel wide.
        paint.anti_alias = false;
        pixmap.fill_rect(rect, &paint, Transform::identity(), None);
    }
}

fn polyline(pixmap: &mut Pixmap, points: &[(f32, f32)], color: Color, width: f32) {
    let mut pb = PathBuilder::new();
    for (i, p) in points.iter().enumerate() {
        if i == 0 {
            pb.move_to(p.0, p.1);
        } else {
            pb.line_to(p.0, p.1);
        }
    }
    if let Some(path) = pb.finish() {
        let mut paint = Paint::default();
        paint.set_color(color);
        paint.anti_alias = true;
        pixmap.stroke_path(&path, &paint, &Stroke { width, ..Stroke::default() }, Transform::identity(), None);
    }
}

pub(super) fn line(pixmap: &mut Pixmap, a: (f32, f32), b: (f32, f32), color: Color, width: f32) {
    polyline(pixmap, &[a, b], color, width);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::deepmimic::rest_pose;

    /// The rest pose walking 3 m along +z under a barrier at 2 < z < 3 whose underside is at
    /// 1.2 m: the barrier's grey shows above the figures where it is, the figures move along
    /// the picture (travel is visible), and nothing is drawn where there is nothing.
    #[test]
    fn draws_the_motion_where_it_is_and_the_barrier() {
        let poses: Vec<Pose> =
            (0..61).map(|t| rest_pose().map(|v| v + DVec3::new(0.0, 0.9, 0.05 * t as f64))).collect();
        let barrier = Primitive::OverheadBarrier(OverheadBarrier {
            underside_height_m: 1.2,
            margin_m: 0.0,
            z_range_m: [2.0, 3.0],
        });
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("strip.png");
        motion_strip(&[StripRow { label: "walk".into(), poses: &poses }], 4, &[barrier], "test", &path).unwrap();
        let png = Pixmap::load_png(&path).unwrap();
        // Geometry as in motion_strip: the z range of every joint, 0.3 m either side.
        let zs = || poses.iter().flatten().map(|v| v.z);
        let (z0, z1) = (zs().fold(f64::INFINITY, f64::min) - 0.3, zs().fold(f64::NEG_INFINITY, f64::max) + 0.3);
        let scale = (MAX_WIDTH_PX / (z1 - z0)).min(MAX_SCALE);
        let top_y = 2.2 + 0.1;
        let ground = LABEL_PX as f64 + 8.0 + LABEL_PX as f64 + top_y * scale;
        let pixel = |z: f64, y: f64| {
            let (px, py) = (MARGIN_PX as f64 + (z - z0) * scale, ground - y * scale);
            png.pixel(px as u32, py as u32).unwrap()
        };
        let barrier_px = pixel(2.5, 2.0);
        assert!(barrier_px.red() < 250 && barrier_px.red() == barrier_px.blue(), "grey barrier: {barrier_px:?}");
        let empty = pixel(1.5, 2.15);
        assert_eq!((empty.red(), empty.green(), empty.blue()), (255, 255, 255));
        // A figure stands at the start and one at the end (z = 3 m): pelvis pixels are coloured.
        let coloured = |z: f64| {
            (-3..=3).any(|d| {
                let p = pixel(z + f64::from(d) * 0.005, 0.9);
                p.red() != 255 || p.green() != 255 || p.blue() != 255
            })
        };
        assert!(coloured(0.0) && coloured(3.0));
        assert!(motion_strip(&[], 4, &[], "", &path).is_err());
    }
}
