//! Motions in world coordinates as one picture: the [`Layout`]'s side view per motion with stick
//! figures at evenly spaced frames drawn where they are, so travel shows, and its top view with
//! every motion's pelvis and foot trajectories. Later frames darker; each figure's time above
//! its head; an object carried between the hands drawn as a disc of its diameter.

use std::path::Path;

use tiny_skia::Color;

use super::draw::disc;
use super::error::{save_png, RenderError};
use super::font::draw_text;
use super::layout::{Layout, StripRow};
use crate::program::{Carry, Primitive};
use crate::skeleton::{Joint, FPS};

/// Draws `figures` evenly spaced frames of every motion in world coordinates, with the scene
/// primitives and the `carried` objects (a disc of the object's diameter at the hands'
/// midpoint), to a PNG at `path`.
pub fn motion_strip(
    rows: &[StripRow<'_>],
    figures: usize,
    scene: &[Primitive],
    carried: &[Carry],
    title: &str,
    path: &Path,
) -> Result<(), RenderError> {
    let figures = figures.max(1);
    let layout = Layout::new(rows, scene)?;
    let mut pixmap = layout.canvas(title)?;
    let grey = Color::from_rgba8(150, 150, 150, 255);
    for (r, row) in rows.iter().enumerate() {
        layout.side_view(&mut pixmap, r, &row.label, scene);
        layout.pelvis_path(&mut pixmap, r, row.poses, 160);
        for f in 0..figures {
            let t = if figures == 1 { 0 } else { f * (row.poses.len() - 1) / (figures - 1) };
            let alpha = (90.0 + 165.0 * f as f32 / figures.max(2).saturating_sub(1) as f32) as u8;
            let pose = &row.poses[t];
            for object in carried {
                let [a, b] = object.hands.map(|j| pose[j.index()]);
                let radius = layout.length_px(object.diameter_m / 2.0);
                disc(&mut pixmap, layout.side_px(r, (a + b) * 0.5), radius, Color::from_rgba8(230, 150, 30, 110));
            }
            layout.figure(&mut pixmap, r, pose, alpha);
            let head = layout.side_px(r, pose[Joint::Head.index()]);
            draw_text(&mut pixmap, &format!("{:.1}S", t as f64 / FPS), head.0 - 8.0, head.1 - 16.0, 1.0, grey);
        }
    }
    layout.top_view(&mut pixmap, rows, scene);
    save_png(&pixmap, path)
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use tiny_skia::Pixmap;

    use super::*;
    use crate::program::OverheadBarrier;
    use crate::skeleton::rest_pose;
    use crate::skeleton::Pose;

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
            x_range_m: None,
        });
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("strip.png");
        let rows = [StripRow { label: "walk".into(), poses: &poses }];
        motion_strip(&rows, 4, std::slice::from_ref(&barrier), &[], "test", &path).unwrap();
        let png = Pixmap::load_png(&path).unwrap();
        let layout = Layout::new(&rows, &[barrier]).unwrap();
        let pixel = |z: f64, y: f64| {
            let (px, py) = layout.side_px(0, DVec3::new(0.0, y, z));
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
        assert!(motion_strip(&[], 4, &[], &[], "", &path).is_err());
    }

    /// A ball 0.4 m across carried between the wrists is drawn as an orange disc centred between
    /// them: 0.12 m in front of the midpoint it is orange, 0.3 m in front it is not.
    #[test]
    fn draws_a_carried_ball_between_the_hands() {
        let poses: Vec<Pose> = (0..2).map(|_| rest_pose().map(|v| v + DVec3::Y * 0.9)).collect();
        let program = crate::program::TaskProgram::from_json(
            r#"{"text": "", "frames": 2, "constraints": [{"id": "c1", "expr": {"op": "carry", "diameter_m": 0.4}}]}"#,
        )
        .unwrap();
        let carried = program.carried_objects();
        assert_eq!(carried.len(), 1);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("strip.png");
        let rows = [StripRow { label: "hold".into(), poses: &poses }];
        motion_strip(&rows, 1, &[], &carried, "test", &path).unwrap();
        let png = Pixmap::load_png(&path).unwrap();
        let layout = Layout::new(&rows, &[]).unwrap();
        let centre = (poses[0][Joint::LeftWrist.index()] + poses[0][Joint::RightWrist.index()]) * 0.5;
        let pixel = |forward: f64| {
            let (px, py) = layout.side_px(0, centre + DVec3::Z * forward);
            png.pixel(px as u32, py as u32).unwrap()
        };
        let inside = pixel(0.12);
        assert!(inside.red() > inside.blue() + 40, "orange inside the ball: {inside:?}");
        let outside = pixel(0.3);
        assert_eq!((outside.red(), outside.green(), outside.blue()), (255, 255, 255));
    }
}
