//! Stroke and fill helpers over tiny-skia, in pixel coordinates (x right, y down).

use tiny_skia::{Color, FillRule, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};

/// Fills the axis-aligned rectangle with corners `a` and `b` (at least 2 px wide).
pub(super) fn fill(pixmap: &mut Pixmap, a: (f32, f32), b: (f32, f32), color: Color) {
    if let Some(rect) = Rect::from_ltrb(a.0.min(b.0), a.1.min(b.1), a.0.max(b.0).max(a.0.min(b.0) + 2.0), a.1.max(b.1))
    {
        let mut paint = Paint::default();
        paint.set_color(color);
        // tiny-skia's anti-aliased rectangle fill asserts on rectangles under a pixel wide.
        paint.anti_alias = false;
        pixmap.fill_rect(rect, &paint, Transform::identity(), None);
    }
}

/// Fills a disc of `radius` px around `centre`, anti-aliased.
pub(super) fn disc(pixmap: &mut Pixmap, centre: (f32, f32), radius: f32, color: Color) {
    if let Some(path) = PathBuilder::from_circle(centre.0, centre.1, radius) {
        let mut paint = Paint::default();
        paint.set_color(color);
        paint.anti_alias = true;
        pixmap.fill_path(&path, &paint, FillRule::Winding, Transform::identity(), None);
    }
}

/// Strokes the open polyline through `points`, `width` px wide, anti-aliased.
pub(super) fn polyline(pixmap: &mut Pixmap, points: &[(f32, f32)], color: Color, width: f32) {
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

/// Strokes the segment from `a` to `b`.
pub(super) fn line(pixmap: &mut Pixmap, a: (f32, f32), b: (f32, f32), color: Color, width: f32) {
    polyline(pixmap, &[a, b], color, width);
}
