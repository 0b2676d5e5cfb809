//! The world-coordinate picture that the strip and the animation share: one side view per
//! motion (z forward to the right, y up) and one shared top view below them (z to the right,
//! x = the character's left up), both on one metric scale, with metre ticks and the task's
//! scene (barriers, hurdles, gaps, walls, boxes). [`Layout`] is measured once from the motions
//! and the scene; its methods draw the static parts and a stick figure at one frame. Left limbs
//! blue, right limbs red, mid-line in the motion's own colour.

use glam::DVec3;
use tiny_skia::{Color, Pixmap};

use super::draw::{fill, line, polyline};
use super::error::RenderError;
use super::font::draw_text;
use crate::program::{BalanceBeam, Gap, Hurdle, InsideBox, OverheadBarrier, Primitive, Wall};
use crate::skeleton::{bones, Joint, Pose};

/// One motion of a strip or an animation.
pub struct StripRow<'a> {
    /// Text drawn above its side view.
    pub label: String,
    /// The motion, 20 fps, world coordinates.
    pub poses: &'a [Pose],
}

/// Distinct colours of the motions (and their trajectories in the top view), RGB.
pub(super) const MOTION_RGB: [(u8, u8, u8); 8] = [
    (0, 114, 178),
    (213, 94, 0),
    (0, 158, 115),
    (204, 121, 167),
    (86, 180, 233),
    (230, 159, 0),
    (120, 120, 120),
    (0, 0, 0),
];
/// Colour of the left limbs, RGB.
pub(super) const LEFT_RGB: (u8, u8, u8) = (40, 80, 220);
/// Colour of the right limbs, RGB.
pub(super) const RIGHT_RGB: (u8, u8, u8) = (220, 50, 40);
const MARGIN_PX: f32 = 40.0;
const LABEL_PX: f32 = 16.0;
/// Height shown in a side view, m (more when a motion reaches higher).
const SIDE_HEIGHT_M: f64 = 2.2;
/// Widest picture, px.
const MAX_WIDTH_PX: f64 = 1800.0;
/// Pixels per metre at most.
const MAX_SCALE: f64 = 160.0;

/// Colour of motion `r` (motion colours repeat past eight motions).
pub(super) fn motion_rgb(r: usize) -> (u8, u8, u8) {
    MOTION_RGB[r % MOTION_RGB.len()]
}

pub(super) fn colour((r, g, b): (u8, u8, u8), alpha: u8) -> Color {
    Color::from_rgba8(r, g, b, alpha)
}

fn grey() -> Color {
    Color::from_rgba8(150, 150, 150, 255)
}

/// Where everything goes: the shown world extents and the metric scale, measured from every
/// joint of every motion and the scene.
pub(super) struct Layout {
    /// Shown z range (both views), m.
    z: (f64, f64),
    /// Shown x range (top view), m.
    x: (f64, f64),
    /// Height shown in each side view, m.
    top_y: f64,
    /// Pixels per metre.
    scale: f64,
    /// Height of one side view with its label and axis, px.
    side_h: f64,
    /// Number of side views.
    rows: usize,
    /// Picture size, px.
    width: f64,
    height: f64,
}

impl Layout {
    /// Measures `rows` and `scene`. Errors when there is no motion, a motion has no frame, or a
    /// joint position is not finite.
    pub(super) fn new(rows: &[StripRow<'_>], scene: &[Primitive]) -> Result<Self, RenderError> {
        if rows.is_empty() || rows.iter().any(|r| r.poses.is_empty()) {
            return Err(RenderError::Empty("no motion to draw".into()));
        }
        let points = || rows.iter().flat_map(|r| r.poses.iter().flatten());
        let finite = |v: &DVec3| v.is_finite();
        if !points().all(finite) {
            return Err(RenderError::Empty("the motion has non-finite joint positions".into()));
        }
        let range = |axis: fn(&DVec3) -> f64| {
            (points().map(axis).fold(f64::INFINITY, f64::min), points().map(axis).fold(f64::NEG_INFINITY, f64::max))
        };
        let (mut z, mut x) = (range(|v| v.z), range(|v| v.x));
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
        Ok(Self { z, x, top_y, scale, side_h, rows: rows.len(), width, height })
    }

    /// Picture width, px.
    pub(super) fn width(&self) -> f32 {
        self.width as f32
    }

    /// A white picture of the layout's size with `title` at the top left.
    pub(super) fn canvas(&self, title: &str) -> Result<Pixmap, RenderError> {
        let (width, height) = (self.width, self.height);
        let mut pixmap = Pixmap::new(width as u32, height as u32)
            .ok_or_else(|| RenderError::Empty(format!("{width:.0}x{height:.0} pixels")))?;
        pixmap.fill(Color::WHITE);
        draw_text(&mut pixmap, &title.to_uppercase(), 4.0, 4.0, 1.5, Color::BLACK);
        Ok(pixmap)
    }

    /// Pixel column of world z (both views).
    fn px_z(&self, v: f64) -> f32 {
        (MARGIN_PX as f64 + (v - self.z.0) * self.scale) as f32
    }

    /// Top edge of side view `r` (its label row), px; `r = rows` is the top view's.
    fn band_top(&self, r: usize) -> f32 {
        (LABEL_PX as f64 + 8.0 + r as f64 * self.side_h) as f32
    }

    /// Pixel row of the ground (y = 0) in side view `r`.
    fn ground(&self, r: usize) -> f32 {
        self.band_top(r) + LABEL_PX + (self.top_y * self.scale) as f32
    }

    /// Where the world point `v` shows in side view `r`, px.
    /// A length in the world (m) in pixels.
    pub(super) fn length_px(&self, metres: f64) -> f32 {
        (metres * self.scale) as f32
    }

    pub(super) fn side_px(&self, r: usize, v: DVec3) -> (f32, f32) {
        (self.px_z(v.z), self.ground(r) - (v.y * self.scale) as f32)
    }

    /// Pixel row of the top view's x axis baseline (its lowest shown x).
    fn top_bottom(&self) -> f32 {
        self.band_top(self.rows) + LABEL_PX + ((self.x.1 - self.x.0) * self.scale) as f32
    }

    /// Pixel row of world x in the top view.
    fn px_x(&self, v: f64) -> f32 {
        self.top_bottom() - ((v - self.x.0) * self.scale) as f32
    }

    /// Where the world point `v` shows in the top view, px.
    pub(super) fn top_px(&self, v: DVec3) -> (f32, f32) {
        (self.px_z(v.z), self.px_x(v.x))
    }

    /// Side view `r` without its motion: label, scene, z axis and height ticks.
    pub(super) fn side_view(&self, pixmap: &mut Pixmap, r: usize, label: &str, scene: &[Primitive]) {
        let (top, ground) = (self.band_top(r), self.ground(r));
        let scale = self.scale;
        draw_text(
            pixmap,
            &format!("{label} - SIDE VIEW").to_uppercase(),
            4.0,
            top + 2.0,
            1.2,
            colour(motion_rgb(r), 255),
        );
        for p in scene {
            if let Some((lo, hi, [z0, z1])) = side_box(p, self.top_y) {
                fill(
                    pixmap,
                    (self.px_z(z0), ground - (hi * scale) as f32),
                    (self.px_z(z1), ground - (lo * scale) as f32),
                    obstacle(),
                );
            }
            if let Primitive::Wall(Wall { point_m, normal, .. }) = p {
                if normal[2].abs() > 0.9 {
                    let wall_z = self.px_z(point_m[2]);
                    line(pixmap, (wall_z, ground), (wall_z, top + LABEL_PX), grey(), 3.0);
                }
            }
        }
        self.z_axis(pixmap, ground);
        for (k, h) in (0..=(self.top_y as usize)).map(|k| (k, k as f64)) {
            let y = ground - (h * scale) as f32;
            line(pixmap, (MARGIN_PX - 6.0, y), (MARGIN_PX, y), grey(), 1.0);
            draw_text(pixmap, &format!("{k}"), MARGIN_PX - 16.0, y - 4.0, 1.0, grey());
        }
    }

    /// The pelvis path of motion `r` over all its frames in its side view, 1 px.
    pub(super) fn pelvis_path(&self, pixmap: &mut Pixmap, r: usize, poses: &[Pose], alpha: u8) {
        let pelvis: Vec<(f32, f32)> = poses.iter().map(|p| self.side_px(r, p[Joint::Pelvis.index()])).collect();
        polyline(pixmap, &pelvis, colour(motion_rgb(r), alpha), 1.0);
    }

    /// The stick figure of `pose` in side view `r`, 2 px bones.
    pub(super) fn figure(&self, pixmap: &mut Pixmap, r: usize, pose: &Pose, alpha: u8) {
        for (parent, child) in bones() {
            let c = match child.name() {
                n if n.starts_with("left_") => colour(LEFT_RGB, alpha),
                n if n.starts_with("right_") => colour(RIGHT_RGB, alpha),
                _ => colour(motion_rgb(r), alpha),
            };
            line(pixmap, self.side_px(r, pose[parent.index()]), self.side_px(r, pose[child.index()]), c, 2.0);
        }
    }

    /// The top view: label, scene, axes and every motion's pelvis (thick) and feet (thin)
    /// trajectories.
    pub(super) fn top_view(&self, pixmap: &mut Pixmap, rows: &[StripRow<'_>], scene: &[Primitive]) {
        let (top, bottom) = (self.band_top(self.rows), self.top_bottom());
        draw_text(
            pixmap,
            "TOP VIEW: PELVIS (THICK) AND FEET (THIN) OF EVERY MOTION",
            4.0,
            top + 2.0,
            1.2,
            Color::BLACK,
        );
        for p in scene {
            for ([z0, z1], [x0, x1]) in top_boxes(p, self.z, self.x) {
                fill(pixmap, (self.px_z(z0), self.px_x(x1)), (self.px_z(z1), self.px_x(x0)), obstacle());
            }
            if let Primitive::BalanceBeam(beam) = p {
                if let Some((a, b)) = beam_ends(beam, self.z) {
                    let width = (2.0 * beam.half_width_m.max(0.01) * self.scale) as f32;
                    line(pixmap, self.top_px(a), self.top_px(b), Color::from_rgba8(190, 140, 60, 140), width.max(2.0));
                }
            }
        }
        self.z_axis(pixmap, bottom);
        let mut k = self.x.0.ceil();
        while k <= self.x.1 {
            let y = self.px_x(k);
            line(pixmap, (MARGIN_PX - 6.0, y), (MARGIN_PX, y), grey(), 1.0);
            draw_text(pixmap, &format!("{}", k.round() as i64), MARGIN_PX - 22.0, y - 4.0, 1.0, grey());
            k += 1.0;
        }
        draw_text(pixmap, "X LEFT", 2.0, top + LABEL_PX, 1.0, grey());
        for (r, row) in rows.iter().enumerate() {
            for (joint, width) in [(Joint::Pelvis, 2.5), (Joint::LeftFoot, 1.0), (Joint::RightFoot, 1.0)] {
                let track: Vec<(f32, f32)> = row.poses.iter().map(|p| self.top_px(p[joint.index()])).collect();
                polyline(pixmap, &track, colour(motion_rgb(r), 220), width);
            }
        }
    }

    /// Metre ticks along z at the baseline `y_px`, labelled, with the axis name at the right.
    fn z_axis(&self, pixmap: &mut Pixmap, y_px: f32) {
        let (z, scale) = (self.z, self.scale);
        line(pixmap, (self.px_z(z.0), y_px), (self.px_z(z.1), y_px), grey(), 1.0);
        let step = if scale < 40.0 { 2.0 } else { 1.0 };
        let mut k = (z.0 / step).ceil() * step;
        while k <= z.1 {
            line(pixmap, (self.px_z(k), y_px), (self.px_z(k), y_px + 6.0), grey(), 1.0);
            draw_text(pixmap, &format!("{}", k.round() as i64), self.px_z(k) - 3.0, y_px + 8.0, 1.0, grey());
            if scale >= 80.0 && k + 0.5 <= z.1 {
                line(pixmap, (self.px_z(k + 0.5), y_px), (self.px_z(k + 0.5), y_px + 3.0), grey(), 1.0);
            }
            k += step;
        }
        draw_text(pixmap, "Z FORWARD (M)", self.px_z(z.1) - 90.0, y_px + 18.0, 1.0, grey());
    }
}

/// Translucent grey of obstacles.
fn obstacle() -> Color {
    Color::from_rgba8(120, 120, 120, 90)
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
        Primitive::OverheadBarrier(OverheadBarrier { x_range_m, .. }) | Primitive::Hurdle(Hurdle { x_range_m, .. }) => {
            *x_range_m
        }
        Primitive::Wall(Wall { point_m, normal, .. }) if normal[0].abs() > 0.9 => Some([point_m[0]; 2]),
        _ => None,
    }
}

/// The ends of a beam's drawn stretch in the ground plane (y = 0): its `extent_m`, or where its
/// line crosses the shown z range; `None` for a beam without a horizontal part.
fn beam_ends(beam: &BalanceBeam, z: (f64, f64)) -> Option<(DVec3, DVec3)> {
    let direction = DVec3::new(beam.direction[0], 0.0, beam.direction[2]).try_normalize()?;
    let point = DVec3::new(beam.point_m[0], 0.0, beam.point_m[2]);
    // `extent_m` runs along the horizontal direction on a horizontal beam, else along the 3-D
    // one, whose ground projection is shorter by this factor.
    let flat = match beam.horizontal {
        true => 1.0,
        false => {
            let along = DVec3::from_array(beam.direction).try_normalize()?;
            DVec3::new(along.x, 0.0, along.z).length()
        }
    };
    let [from, to] = match beam.extent_m {
        Some([from, to]) => [from * flat, to * flat],
        None if direction.z.abs() > 1e-6 => {
            let (a, b) = ((z.0 - point.z) / direction.z, (z.1 - point.z) / direction.z);
            [a.min(b), a.max(b)]
        }
        None => return None,
    };
    Some((point + direction * from, point + direction * to))
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
/// gap, the outside of a box's x range, a wall's slab 5 cm thick, the footprint of a barrier or
/// hurdle that covers part of the width (one spanning it is drawn in the side view only).
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
        Primitive::OverheadBarrier(OverheadBarrier { x_range_m: Some(xr), z_range_m, .. })
        | Primitive::Hurdle(Hurdle { x_range_m: Some(xr), z_range_m, .. }) => vec![(*z_range_m, *xr)],
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::rest_pose;

    /// A beam's drawn stretch: its extent along a horizontal direction, along the ground
    /// projection of a sloping one, or the shown z range when it is endless.
    #[test]
    fn beams_are_drawn_over_their_stretch() {
        let beam = |direction: [f64; 3], horizontal: bool, extent_m: Option<[f64; 2]>| BalanceBeam {
            point_m: [0.5, 0.1, 0.0],
            direction,
            half_width_m: 0.05,
            horizontal,
            extent_m,
        };
        let (a, b) = beam_ends(&beam([0.0, 0.0, 2.0], true, Some([1.0, 3.0])), (-1.0, 6.0)).unwrap();
        assert!((a - DVec3::new(0.5, 0.0, 1.0)).length() < 1e-12 && (b - DVec3::new(0.5, 0.0, 3.0)).length() < 1e-12);
        // Rising at 45°: 2 m along it is √2 m along the ground.
        let (_, b) = beam_ends(&beam([0.0, 1.0, 1.0], false, Some([0.0, 2.0])), (-1.0, 6.0)).unwrap();
        assert!((b.z - 2f64.sqrt()).abs() < 1e-12);
        let (a, b) = beam_ends(&beam([0.0, 0.0, 1.0], false, None), (-1.0, 6.0)).unwrap();
        assert_eq!((a.z, b.z), (-1.0, 6.0));
        assert!(beam_ends(&beam([0.0, 1.0, 0.0], false, None), (-1.0, 6.0)).is_none());
    }

    /// One motion 3 m along +z with a gap 1 m wide beside it: the layout spans the motion plus
    /// 0.3 m either side and the gap's walls, and world points land where the axes say.
    #[test]
    fn measures_the_motion_and_the_scene() {
        let poses: Vec<Pose> =
            (0..61).map(|t| rest_pose().map(|v| v + DVec3::new(0.0, 0.9, 0.05 * t as f64))).collect();
        let gap = Primitive::Gap(Gap { centre_x_m: 0.0, width_m: 1.0, margin_m: 0.0, z_range_m: Some([1.0, 2.0]) });
        let layout = Layout::new(&[StripRow { label: "walk".into(), poses: &poses }], &[gap]).unwrap();
        assert!(layout.x.0 <= -1.2 && layout.x.1 >= 1.2, "x {:?}", layout.x);
        let zs = || poses.iter().flatten().map(|v| v.z);
        assert!((layout.z.0 - (zs().fold(f64::INFINITY, f64::min) - 0.3)).abs() < 1e-12);
        let a = layout.side_px(0, DVec3::new(0.0, 0.0, 1.0));
        let b = layout.side_px(0, DVec3::new(0.0, 1.0, 2.0));
        assert!(((b.0 - a.0) as f64 - layout.scale).abs() < 1.0 && ((a.1 - b.1) as f64 - layout.scale).abs() < 1.0);
        let (left, right) = (layout.top_px(DVec3::new(1.0, 0.0, 0.0)), layout.top_px(DVec3::new(-1.0, 0.0, 0.0)));
        assert!(left.1 < right.1, "+x (left) is up in the top view");
        assert!(layout.top_px(DVec3::ZERO).1 > layout.ground(0), "the top view is below the side view");
        assert!(layout.canvas("t").is_ok());
    }

    #[test]
    fn refuses_no_motion_and_non_finite_joints() {
        assert!(matches!(Layout::new(&[], &[]), Err(RenderError::Empty(_))));
        let mut pose = rest_pose();
        assert!(Layout::new(&[StripRow { label: "a".into(), poses: &[] }], &[]).is_err());
        pose[3].y = f64::NAN;
        assert!(Layout::new(&[StripRow { label: "a".into(), poses: &[pose] }], &[]).is_err());
    }
}
