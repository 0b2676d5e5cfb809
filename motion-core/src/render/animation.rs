//! Motions in world coordinates as an animated GIF: the strip's [`Layout`] (a side view per
//! motion, one shared top view) where each GIF frame shows every motion's figure at that time
//! over its faint whole pelvis path, a dot at each motion's current pelvis in the top view over
//! the full trajectories, and the time. Motions shorter than the longest hold their last pose.
//!
//! The picture has few colours, so a fixed palette (a grey ramp and tints of each drawing colour
//! towards white, which covers anti-aliased edges over white) replaces a quantiser. Every frame
//! after the first stores only the rectangle that changed, its unchanged pixels transparent:
//! a 100-frame, 4-motion GIF stays well under 3 MB.

use std::borrow::Cow;
use std::path::Path;

use gif::{DisposalMethod, Encoder, Frame, Repeat};
use tiny_skia::{Color, Pixmap};

use super::draw::disc;
use super::error::RenderError;
use super::font::{char_width, draw_text};
use super::layout::{colour, motion_rgb, Layout, StripRow, LEFT_RGB, MOTION_RGB, RIGHT_RGB};
use crate::files::{write_atomically, WriteError};
use crate::program::Primitive;
use crate::skeleton::{Joint, FPS};

/// Options of [`motion_gif`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GifOptions {
    /// Motion frames (20 fps) per GIF frame: 1 plays every frame (GIF delay 5 cs), 2 every other
    /// frame (10 cs), and so on; 0 counts as 1. Default 1.
    pub frame_step: usize,
    /// How long the last frame stays before the loop starts again, centiseconds. Default 100.
    pub end_hold_cs: u16,
}

impl Default for GifOptions {
    fn default() -> Self {
        Self { frame_step: 1, end_hold_cs: 100 }
    }
}

/// Opacity of the whole pelvis path behind the moving figure (the strip's is 160).
const PATH_ALPHA: u8 = 90;
/// Radius of the current-pelvis dot in the top view, px (inside a 1.5 px black ring).
const DOT_PX: f32 = 4.0;

/// Animates every motion in world coordinates with the scene primitives and writes the GIF to
/// `path` atomically (nothing is written on error). Frame `i` shows motion frame
/// `i * frame_step`; the GIF has `ceil(longest / frame_step)` frames and loops forever.
pub fn motion_gif(
    rows: &[StripRow<'_>],
    scene: &[Primitive],
    title: &str,
    options: &GifOptions,
    path: &Path,
) -> Result<(), RenderError> {
    let write_error = |message: String| RenderError::Write { path: path.into(), message };
    let layout = Layout::new(rows, scene)?;
    let mut background = layout.canvas(title)?;
    for (r, row) in rows.iter().enumerate() {
        layout.side_view(&mut background, r, &row.label, scene);
        layout.pelvis_path(&mut background, r, row.poses, PATH_ALPHA);
    }
    layout.top_view(&mut background, rows, scene);
    let size = |n: u32| u16::try_from(n).map_err(|_| RenderError::Empty(format!("{n} pixels is too large for a GIF")));
    let (width, height) = (size(background.width())?, size(background.height())?);

    let step = options.frame_step.max(1);
    let frames = rows.iter().map(|r| r.poses.len()).max().unwrap_or(0).div_ceil(step);
    let delay_cs = u16::try_from((step as f64 * 100.0 / FPS).round() as u64).unwrap_or(u16::MAX);
    let mut palette = Palette::new();
    let mut encoder = Encoder::new(Vec::new(), width, height, &palette.rgb).map_err(|e| write_error(e.to_string()))?;
    encoder.set_repeat(Repeat::Infinite).map_err(|e| write_error(e.to_string()))?;
    let mut previous: Option<Vec<u8>> = None;
    for i in 0..frames {
        let t = i * step;
        let mut pixmap = background.clone();
        for (r, row) in rows.iter().enumerate() {
            let pose = &row.poses[t.min(row.poses.len() - 1)];
            layout.figure(&mut pixmap, r, pose, 255);
            let pelvis = layout.top_px(pose[Joint::Pelvis.index()]);
            disc(&mut pixmap, pelvis, DOT_PX + 1.5, Color::BLACK);
            disc(&mut pixmap, pelvis, DOT_PX, colour(motion_rgb(r), 255));
        }
        let readout = format!("{:.2} S", t as f64 / FPS);
        let readout_x = layout.width() - char_width(1.5) * readout.len() as f32 - 8.0;
        draw_text(&mut pixmap, &readout, readout_x, 4.0, 1.5, Color::BLACK);
        let indices = palette.indices(&pixmap);
        let mut frame = match &previous {
            None => Frame { width, height, buffer: Cow::Borrowed(&indices), ..Frame::default() },
            Some(previous) => difference_frame(previous, &indices, width),
        };
        frame.delay = if i + 1 == frames { options.end_hold_cs.max(delay_cs) } else { delay_cs };
        frame.dispose = DisposalMethod::Keep;
        encoder.write_frame(&frame).map_err(|e| write_error(e.to_string()))?;
        previous = Some(indices);
    }
    let bytes = encoder.into_inner().map_err(|e| write_error(e.to_string()))?;
    write_atomically(path, &bytes).map_err(|WriteError { path, message }| RenderError::Write { path, message })
}

/// Palette index that marks a pixel unchanged since the previous frame.
const TRANSPARENT: u8 = 255;
/// Levels of the grey ramp from black to white.
const GREY_LEVELS: usize = 32;

/// The fixed GIF palette and each 24-bit colour's nearest entry, found on first use.
struct Palette {
    /// The colours, RGB.
    colours: Vec<[u8; 3]>,
    /// 256 RGB triples, flat (the colours, then white); entry [`TRANSPARENT`] is never chosen.
    rgb: Vec<u8>,
    /// Nearest entry of each colour `r << 16 | g << 8 | b`; [`TRANSPARENT`] where not yet found.
    nearest: Vec<u8>,
}

impl Palette {
    /// A grey ramp and, for each drawing colour that is not grey (the motions', the left and
    /// right limbs'), an even ramp of tints from the colour to just short of white.
    fn new() -> Self {
        let mut colours: Vec<[u8; 3]> = (0..GREY_LEVELS)
            .map(|k| {
                let v = (k * 255 / (GREY_LEVELS - 1)) as u8;
                [v; 3]
            })
            .collect();
        let hues: Vec<(u8, u8, u8)> =
            MOTION_RGB.into_iter().chain([LEFT_RGB, RIGHT_RGB]).filter(|&(r, g, b)| !(r == g && g == b)).collect();
        let tints = (usize::from(TRANSPARENT) - GREY_LEVELS) / hues.len().max(1);
        for (r, g, b) in hues {
            for k in 0..tints {
                let tint = |c: u8| (f64::from(c) + (255.0 - f64::from(c)) * k as f64 / tints as f64).round() as u8;
                colours.push([tint(r), tint(g), tint(b)]);
            }
        }
        let mut rgb = colours.concat();
        rgb.resize(256 * 3, 255);
        Self { colours, rgb, nearest: vec![TRANSPARENT; 1 << 24] }
    }

    /// Palette indices of an opaque picture, row by row.
    fn indices(&mut self, pixmap: &Pixmap) -> Vec<u8> {
        pixmap
            .pixels()
            .iter()
            .map(|p| {
                let c = p.demultiply();
                let key = (usize::from(c.red()) << 16) | (usize::from(c.green()) << 8) | usize::from(c.blue());
                if self.nearest[key] == TRANSPARENT {
                    self.nearest[key] = self.closest([c.red(), c.green(), c.blue()]);
                }
                self.nearest[key]
            })
            .collect()
    }

    /// The entry nearest `c` in RGB distance.
    fn closest(&self, c: [u8; 3]) -> u8 {
        let distance = |e: &[u8; 3]| -> u32 { (0..3).map(|i| u32::from(e[i].abs_diff(c[i])).pow(2)).sum() };
        (0..self.colours.len()).min_by_key(|&i| distance(&self.colours[i])).unwrap_or(0) as u8
    }
}

/// The frame that turns `previous` into `current` (palette indices, `width` per row) when drawn
/// over it: the smallest rectangle holding every changed pixel with its unchanged pixels
/// [`TRANSPARENT`], or one transparent pixel when nothing changed.
fn difference_frame(previous: &[u8], current: &[u8], width: u16) -> Frame<'static> {
    let w = usize::from(width).max(1);
    let mut bounds: Option<(usize, usize, usize, usize)> = None;
    for (y, (old, new)) in previous.chunks_exact(w).zip(current.chunks_exact(w)).enumerate() {
        let mut changed = old.iter().zip(new).enumerate().filter(|(_, (a, b))| a != b).map(|(x, _)| x);
        if let Some(first) = changed.next() {
            let last = changed.next_back().unwrap_or(first);
            bounds = Some(match bounds {
                None => (first, y, last, y),
                Some((x0, y0, x1, _)) => (x0.min(first), y0, x1.max(last), y),
            });
        }
    }
    let Some((x0, y0, x1, y1)) = bounds else {
        return Frame {
            width: 1,
            height: 1,
            transparent: Some(TRANSPARENT),
            buffer: vec![TRANSPARENT].into(),
            ..Frame::default()
        };
    };
    let mut buffer = Vec::with_capacity((x1 - x0 + 1) * (y1 - y0 + 1));
    for y in y0..=y1 {
        let row = y * w;
        buffer.extend(previous[row + x0..=row + x1].iter().zip(&current[row + x0..=row + x1]).map(|(&a, &b)| {
            if a == b {
                TRANSPARENT
            } else {
                b
            }
        }));
    }
    // The bounds lie inside a picture whose sides fit in u16.
    let side = |n: usize| u16::try_from(n).unwrap_or(u16::MAX);
    Frame {
        left: side(x0),
        top: side(y0),
        width: side(x1 - x0 + 1),
        height: side(y1 - y0 + 1),
        transparent: Some(TRANSPARENT),
        buffer: buffer.into(),
        ..Frame::default()
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::import::deepmimic::{shipped, DeepMimicClip};
    use crate::import::MocapClip;
    use crate::program::OverheadBarrier;
    use crate::skeleton::rest_pose;
    use crate::skeleton::Pose;

    /// A decoded GIF: its size, each frame's delay, and each frame composited over the ones
    /// before (RGBA), as a viewer shows it.
    struct Decoded {
        size: (u16, u16),
        delays: Vec<u16>,
        pictures: Vec<Vec<u8>>,
    }

    fn decode(path: &Path) -> Decoded {
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options.read_info(std::fs::File::open(path).unwrap()).unwrap();
        let size = (decoder.width(), decoder.height());
        let w = usize::from(size.0);
        let mut canvas = vec![0u8; w * usize::from(size.1) * 4];
        let (mut delays, mut pictures) = (Vec::new(), Vec::new());
        while let Some(frame) = decoder.read_next_frame().unwrap() {
            assert_eq!(frame.dispose, DisposalMethod::Keep);
            let (left, top, fw) = (usize::from(frame.left), usize::from(frame.top), usize::from(frame.width));
            for (i, px) in frame.buffer.chunks_exact(4).enumerate() {
                if px[3] != 0 {
                    let at = ((top + i / fw) * w + left + i % fw) * 4;
                    canvas[at..at + 4].copy_from_slice(px);
                }
            }
            delays.push(frame.delay);
            pictures.push(canvas.clone());
        }
        Decoded { size, delays, pictures }
    }

    /// The rest pose walking along +z at 1 m/s, `frames` long, `x_m` to the side.
    fn walk(frames: usize, x_m: f64) -> Vec<Pose> {
        (0..frames).map(|t| rest_pose().map(|v| v + DVec3::new(x_m, 0.9, 0.05 * t as f64))).collect()
    }

    /// Two motions of 30 and 20 frames: 30 GIF frames the size of the strip's layout at 5 cs
    /// (the last held 1 s), each one different from the one before (the longer motion moves
    /// on after the shorter one stops); every other frame gives 15 frames at 10 cs.
    #[test]
    fn plays_every_frame_of_the_longest_motion() {
        let (a, b) = (walk(30, 0.0), walk(20, 0.5));
        let rows = [StripRow { label: "a".into(), poses: &a }, StripRow { label: "b".into(), poses: &b }];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("motion.gif");
        motion_gif(&rows, &[], "two walks", &GifOptions::default(), &path).unwrap();
        let gif = decode(&path);
        let canvas = Layout::new(&rows, &[]).unwrap().canvas("").unwrap();
        assert_eq!((u32::from(gif.size.0), u32::from(gif.size.1)), (canvas.width(), canvas.height()));
        assert_eq!(gif.delays.len(), 30);
        assert!(gif.delays[..29].iter().all(|&d| d == 5) && gif.delays[29] == 100, "{:?}", gif.delays);
        assert!(gif.pictures.iter().all(|p| p.chunks_exact(4).all(|px| px[3] == 255)), "every pixel painted");
        for (i, pair) in gif.pictures.windows(2).enumerate() {
            assert_ne!(pair[0], pair[1], "frames {i} and {}", i + 1);
        }

        let options = GifOptions { frame_step: 2, end_hold_cs: 0 };
        motion_gif(&rows, &[], "two walks", &options, &path).unwrap();
        let gif = decode(&path);
        assert_eq!(gif.delays, vec![10; 15]);
    }

    /// A figure shows where its pose is: the first frame has the figure's colour at the pelvis
    /// of frame 0 and white at the pelvis of the last frame, the last frame the other way round.
    #[test]
    fn draws_each_frame_pose_where_it_is() {
        let poses = walk(41, 0.0);
        let rows = [StripRow { label: "walk".into(), poses: &poses }];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("walk.gif");
        motion_gif(&rows, &[], "walk", &GifOptions::default(), &path).unwrap();
        let gif = decode(&path);
        let layout = Layout::new(&rows, &[]).unwrap();
        let w = usize::from(gif.size.0);
        // Whether a 5×5 block around the pelvis of `pose` (0.1 m above it: the spine) is drawn
        // in something darker than the faint path.
        let figure_at = |picture: &[u8], pose: &Pose| {
            let (x, y) = layout.side_px(0, pose[Joint::Pelvis.index()] + DVec3::new(0.0, 0.1, 0.0));
            (-2..=2).any(|dx: i32| {
                (-2..=2).any(|dy: i32| {
                    let at = ((y as i32 + dy) as usize * w + (x as i32 + dx) as usize) * 4;
                    picture[at..at + 3].iter().map(|&c| u32::from(c)).sum::<u32>() < 450
                })
            })
        };
        let (first, last) = (&gif.pictures[0], &gif.pictures[40]);
        assert!(figure_at(first, &poses[0]) && !figure_at(first, &poses[40]));
        assert!(figure_at(last, &poses[40]) && !figure_at(last, &poses[0]));
    }

    #[test]
    fn refuses_bad_motions_or_paths_and_writes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("motion.gif");
        let options = GifOptions::default();
        assert!(matches!(motion_gif(&[], &[], "", &options, &path), Err(RenderError::Empty(_))));
        let empty = [StripRow { label: "a".into(), poses: &[] }];
        assert!(motion_gif(&empty, &[], "", &options, &path).is_err());
        let mut poses = walk(10, 0.0);
        poses[4][7].z = f64::INFINITY;
        let bad = [StripRow { label: "a".into(), poses: &poses }];
        assert!(motion_gif(&bad, &[], "", &options, &path).is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "nothing written");
        // A folder where the file should go: the write fails, naming the path, and leaves no
        // temporary file behind.
        let folder = dir.path().join("taken");
        std::fs::create_dir(&folder).unwrap();
        let good = walk(3, 0.0);
        let rows = [StripRow { label: "a".into(), poses: &good }];
        let error = motion_gif(&rows, &[], "", &options, &folder).unwrap_err();
        assert!(matches!(&error, RenderError::Write { path, .. } if *path == folder), "{error}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    /// The difference of two 4×3 pictures is the rectangle around the changed pixels with the
    /// unchanged ones inside it transparent; no change is one transparent pixel.
    #[test]
    fn difference_frames_hold_only_what_changed() {
        let before = vec![0u8; 12];
        let mut after = before.clone();
        after[4 + 1] = 7;
        after[2 * 4 + 2] = 9;
        let frame = difference_frame(&before, &after, 4);
        assert_eq!((frame.left, frame.top, frame.width, frame.height), (1, 1, 2, 2));
        assert_eq!(frame.buffer.as_ref(), [7, TRANSPARENT, TRANSPARENT, 9]);
        let still = difference_frame(&before, &before, 4);
        assert_eq!((still.width, still.height, still.buffer.as_ref()), (1, 1, &[TRANSPARENT][..]));
        assert_eq!(still.transparent, Some(TRANSPARENT));
    }

    /// White, black and the drawing colours are in the palette exactly, the axes' grey nearly;
    /// anti-aliased edges of the limb colours over white keep their hue; every entry maps to
    /// itself and never to the transparent one.
    #[test]
    fn palette_keeps_the_drawing_colours() {
        let mut palette = Palette::new();
        let table = palette.rgb.clone();
        let mut index = |(r, g, b): (u8, u8, u8)| {
            let mut pixmap = Pixmap::new(1, 1).unwrap();
            pixmap.fill(Color::from_rgba8(r, g, b, 255));
            palette.indices(&pixmap)[0]
        };
        let rgb = |i: u8| {
            let at = usize::from(i) * 3;
            (table[at], table[at + 1], table[at + 2])
        };
        for c in [(255, 255, 255), (0, 0, 0), LEFT_RGB, RIGHT_RGB, MOTION_RGB[0], MOTION_RGB[5]] {
            assert_eq!(rgb(index(c)), c);
        }
        let axes = rgb(index((150, 150, 150)));
        assert!(axes.0 == axes.1 && axes.1 == axes.2 && axes.0.abs_diff(150) <= 4, "{axes:?}");
        let half_red = rgb(index((238, 153, 148)));
        assert!(half_red.0 > half_red.1 + 60 && half_red.0 > half_red.2 + 60, "{half_red:?}");
        for i in 0..TRANSPARENT {
            let back = index(rgb(i));
            assert!(back != TRANSPARENT && rgb(back) == rgb(i), "entry {i}");
        }
    }

    /// Four real motions of 100 frames (the DeepMimic walk, run and jump and the walk beside
    /// them) under an overhead barrier: 100 frames, well under 3 MB.
    #[test]
    fn animates_real_clips_in_a_small_file() {
        let clip = shipped::clip;
        let motion = |clip: &DeepMimicClip, shift: DVec3| -> Vec<Pose> {
            (0..100).map(|k| clip.pose_at(k as f64 / FPS).map(|v| v + shift)).collect()
        };
        let (walk, run) = (clip("humanoid3d_walk.txt"), clip("humanoid3d_run.txt"));
        let motions = [
            motion(&walk, DVec3::ZERO),
            motion(&run, DVec3::ZERO),
            motion(&clip("humanoid3d_jump.txt"), DVec3::ZERO),
            motion(&walk, DVec3::new(1.0, 0.0, 0.0)),
        ];
        let rows: Vec<StripRow<'_>> = ["walk", "run", "jump", "walk 1 m left"]
            .iter()
            .zip(&motions)
            .map(|(label, poses)| StripRow { label: (*label).into(), poses })
            .collect();
        let barrier = Primitive::OverheadBarrier(OverheadBarrier {
            underside_height_m: 1.5,
            margin_m: 0.0,
            z_range_m: [2.0, 2.5],
            x_range_m: None,
        });
        let out = tempfile::tempdir().unwrap();
        let path = out.path().join("motion.gif");
        motion_gif(&rows, &[barrier], "four clips under a barrier", &GifOptions::default(), &path).unwrap();
        let bytes = std::fs::metadata(&path).unwrap().len();
        assert!(bytes < 3_000_000, "{bytes} bytes");
        assert_eq!(decode(&path).delays.len(), 100);
    }
}
