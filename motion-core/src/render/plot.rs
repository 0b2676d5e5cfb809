//! Line plots (loss curves and the like) with labelled axes.

use std::path::Path;

use tiny_skia::{Color, Pixmap};

use super::draw::line;
use super::error::{save_png, RenderError};
use super::font::{char_width, draw_text};

/// One line of a plot.
pub struct Series<'a> {
    /// Legend text.
    pub name: &'a str,
    /// (x, y) points.
    pub points: &'a [(f64, f64)],
    /// RGB colour.
    pub rgb: (u8, u8, u8),
}

/// Draws series on shared axes to a PNG; `log_y` plots log10(y) (non-positive values skipped).
pub fn line_plot(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    log_y: bool,
    path: &Path,
) -> Result<(), RenderError> {
    let ty = |y: f64| if log_y { (y > 0.0).then(|| y.log10()) } else { Some(y) };
    let pts: Vec<(f64, f64)> =
        series.iter().flat_map(|s| s.points.iter().filter_map(|(x, y)| ty(*y).map(|y| (*x, y)))).collect();
    if pts.is_empty() {
        return Err(RenderError::Empty("no points".into()));
    }
    let (x0, x1) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let (y0, y1) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| (a.0.min(p.1), a.1.max(p.1)));
    let (x1, y1) = (if x1 > x0 { x1 } else { x0 + 1.0 }, if y1 > y0 { y1 } else { y0 + 1.0 });
    let (w, h, left, bottom, top, right) = (720.0f32, 420.0f32, 70.0f32, 50.0f32, 40.0f32, 20.0f32);
    let mut pixmap = Pixmap::new(w as u32, h as u32).ok_or_else(|| RenderError::Empty("size".into()))?;
    pixmap.fill(Color::WHITE);
    let px = |x: f64, y: f64| {
        (
            left + ((x - x0) / (x1 - x0)) as f32 * (w - left - right),
            h - bottom - ((y - y0) / (y1 - y0)) as f32 * (h - top - bottom),
        )
    };
    let grey = Color::from_rgba8(120, 120, 120, 255);
    line(&mut pixmap, (left, h - bottom), (w - right, h - bottom), Color::BLACK, 1.0);
    line(&mut pixmap, (left, top), (left, h - bottom), Color::BLACK, 1.0);
    for k in 0..=4 {
        let f = k as f64 / 4.0;
        let (gx, gy) = (x0 + f * (x1 - x0), y0 + f * (y1 - y0));
        let (sx, _) = px(gx, y0);
        let (_, sy) = px(x0, gy);
        line(&mut pixmap, (sx, h - bottom), (sx, h - bottom + 4.0), Color::BLACK, 1.0);
        line(&mut pixmap, (left - 4.0, sy), (left, sy), Color::BLACK, 1.0);
        draw_text(&mut pixmap, &format!("{gx:.0}"), sx - 10.0, h - bottom + 8.0, 1.0, grey);
        let yl = if log_y { format!("{:.3}", 10f64.powf(gy)) } else { format!("{gy:.3}") };
        draw_text(&mut pixmap, &yl, 4.0, sy - 3.0, 1.0, grey);
    }
    draw_text(&mut pixmap, title, left, 12.0, 2.0, Color::BLACK);
    draw_text(
        &mut pixmap,
        x_label,
        w / 2.0 - x_label.len() as f32 * char_width(1.5) / 2.0,
        h - 22.0,
        1.5,
        Color::BLACK,
    );
    draw_text(&mut pixmap, y_label, 4.0, top - 14.0, 1.0, Color::BLACK);
    for (i, s) in series.iter().enumerate() {
        let color = Color::from_rgba8(s.rgb.0, s.rgb.1, s.rgb.2, 255);
        let pts: Vec<(f32, f32)> = s.points.iter().filter_map(|(x, y)| ty(*y).map(|y| px(*x, y))).collect();
        for seg in pts.windows(2) {
            line(&mut pixmap, seg[0], seg[1], color, 1.2);
        }
        let ly = top + 4.0 + 12.0 * i as f32;
        line(&mut pixmap, (w - 190.0, ly + 3.0), (w - 170.0, ly + 3.0), color, 2.0);
        draw_text(&mut pixmap, s.name, w - 165.0, ly, 1.0, Color::BLACK);
    }
    save_png(&pixmap, path)
}
