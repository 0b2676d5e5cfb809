//! [`Bvh`]: a BVH file as written (hierarchy, frame time, channel values per frame).

use std::path::Path;

use glam::DVec3;

use super::error::invalid;
use super::hierarchy::{parse_hierarchy, BvhJoint, Channel};
use super::units::UpAxis;
use crate::files::read_bytes;
use crate::import::error::{ImportError, ImportWarning};
use crate::import::values::{check_clip_length, parse_finite, short_number};
use crate::limits::MOCAP_FILE_BYTES;

/// A parsed BVH file with values as written (file units, degrees, file axes).
#[derive(Debug, Clone)]
pub struct Bvh {
    joints: Vec<BvhJoint>,
    frame_time_s: f64,
    /// `[frames, channel_count]`, row-major.
    motion: Vec<f64>,
    channel_count: usize,
    /// 1-based line of each frame (blank lines are skipped, so they are not consecutive).
    frame_lines: Vec<usize>,
}

/// Accepted `Frame Time` range, s: 10,000 to 1 frames per second.
const FRAME_TIME_S: (f64, f64) = (1e-4, 1.0);

impl Bvh {
    /// Reads a file of at most [`MOCAP_FILE_BYTES`] (non-UTF-8 bytes are replaced, so only
    /// names can suffer).
    pub fn read(path: &Path) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let bytes = read_bytes(path, &MOCAP_FILE_BYTES)?;
        Self::parse(&String::from_utf8_lossy(&bytes), path)
    }

    /// Parses BVH text; `path` is only used in messages. Warns about lines after the last frame.
    ///
    /// Nothing is allocated per line or per token: the hierarchy is read as a stream and is
    /// refused at its [`RIG_JOINTS`](crate::limits::RIG_JOINTS)+1st node; the frame time and the clip's length at 20 fps
    /// ([`check_clip_length`]) are checked from the header before the motion is read.
    pub fn parse(text: &str, path: &Path) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let numbered = || text.lines().enumerate().map(|(i, l)| (i + 1, l));
        if text.lines().all(|l| l.trim().is_empty()) {
            return Err(invalid(path, 1, None, "empty file; expected HIERARCHY"));
        }
        let motion_at = text.lines().position(|l| l.split_whitespace().next() == Some("MOTION"));
        let hierarchy_end = motion_at.unwrap_or_else(|| text.lines().count());
        let tokens = numbered().take(hierarchy_end).flat_map(|(line, l)| l.split_whitespace().map(move |t| (t, line)));
        let joints = parse_hierarchy(tokens, hierarchy_end.max(1), path)?;
        let channel_count: usize = joints.iter().map(|j| j.channels.len()).sum();
        if channel_count == 0 {
            return Err(invalid(path, joints[0].line, None, "the hierarchy declares no channels"));
        }
        let Some(motion_at) = motion_at else {
            return Err(invalid(path, hierarchy_end, None, "file ends without a MOTION section"));
        };
        let mut rest = numbered().skip(motion_at + 1).filter(|(_, l)| !l.trim().is_empty());
        let (declared, frames_line, frame_time_s) = read_motion_header(&mut rest, motion_at, path)?;
        let owners: Vec<(usize, Channel)> =
            joints.iter().enumerate().flat_map(|(j, joint)| joint.channels.iter().map(move |c| (j, *c))).collect();
        // Every value takes at least two bytes of text, so the file's size bounds the table.
        let mut motion = Vec::with_capacity(declared.saturating_mul(channel_count).min(text.len() / 2));
        let mut frame_lines = Vec::with_capacity(declared.min(text.len() / 2));
        let mut extra_lines = 0;
        for (line, text) in rest {
            if frame_lines.len() == declared {
                extra_lines += 1;
                continue;
            }
            read_frame(text, line, frame_lines.len(), &owners, &joints, path, &mut motion)?;
            frame_lines.push(line);
        }
        let frames = frame_lines.len();
        if frames < declared {
            return Err(invalid(
                path,
                text.lines().count(),
                None,
                format!("file ends after {frames} of the {declared} frames declared on line {frames_line}"),
            ));
        }
        let warnings = if extra_lines > 0 {
            vec![ImportWarning {
                path: path.into(),
                message: format!(
                    "ignored {extra_lines} lines after the {declared} frames declared on line {frames_line}"
                ),
            }]
        } else {
            Vec::new()
        };
        Ok((Self { joints, frame_time_s, motion, channel_count, frame_lines }, warnings))
    }

    /// The hierarchy, parents before children, root first.
    pub fn joints(&self) -> &[BvhJoint] {
        &self.joints
    }

    /// Number of frames (at least 1).
    pub fn frames(&self) -> usize {
        self.motion.len() / self.channel_count
    }

    /// Seconds between frames.
    pub fn frame_time_s(&self) -> f64 {
        self.frame_time_s
    }

    /// 1-based line of frame `k` in the file.
    pub fn frame_line(&self, k: usize) -> Option<usize> {
        self.frame_lines.get(k).copied()
    }

    /// Channel values of frame `k`, in hierarchy order.
    pub fn frame(&self, k: usize) -> Option<&[f64]> {
        let start = k.checked_mul(self.channel_count)?;
        self.motion.get(start..start.checked_add(self.channel_count)?)
    }

    /// Index of the joint (not end site) with this name, ignoring a namespace prefix such as
    /// `mixamorig:` and ASCII case.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| {
            let bare = j.name.rsplit(':').next().unwrap_or(&j.name);
            !j.end_site && bare.eq_ignore_ascii_case(name)
        })
    }

    /// Index of the End Site whose parent is node `joint` (the first, if it has several).
    pub fn end_site_of(&self, joint: usize) -> Option<usize> {
        self.joints.iter().position(|j| j.end_site && j.parent == Some(joint))
    }

    /// Vertical extent of the rest skeleton (OFFSETs only, end sites included), file units.
    pub fn rest_height(&self, up: UpAxis) -> f64 {
        let mut pos = vec![DVec3::ZERO; self.joints.len()];
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (j, joint) in self.joints.iter().enumerate() {
            pos[j] = joint.parent.map_or(DVec3::ZERO, |p| pos[p]) + joint.offset;
            let h = up.to_ours(pos[j]).y;
            lo = lo.min(h);
            hi = hi.max(h);
        }
        hi - lo
    }
}

/// The `Frames:` and `Frame Time:` lines after `MOTION` (on line `motion_at`, 0-based):
/// `(frames, 1-based line of Frames:, frame time s)`. The frame time must be within
/// [`FRAME_TIME_S`] and the clip's length at 20 fps within [`check_clip_length`]'s limit.
fn read_motion_header<'a>(
    rest: &mut impl Iterator<Item = (usize, &'a str)>,
    motion_at: usize,
    path: &Path,
) -> Result<(usize, usize, f64), ImportError> {
    let (frames_line, frames_text) =
        rest.next().ok_or_else(|| invalid(path, motion_at + 1, None, "MOTION is not followed by `Frames:`"))?;
    let declared = header_value(frames_text, "Frames:").and_then(|v| v.parse::<usize>().ok()).ok_or_else(|| {
        invalid(path, frames_line, None, format!("expected `Frames: <count>`, found `{}`", frames_text.trim()))
    })?;
    if declared == 0 {
        return Err(ImportError::Empty { path: path.into() });
    }
    let (time_line, time_text) =
        rest.next().ok_or_else(|| invalid(path, frames_line, None, "`Frames:` is not followed by `Frame Time:`"))?;
    let frame_time_s = header_value(time_text, "Frame Time:").and_then(parse_finite).ok_or_else(|| {
        invalid(path, time_line, None, format!("expected `Frame Time: <seconds>`, found `{}`", time_text.trim()))
    })?;
    if !(FRAME_TIME_S.0..=FRAME_TIME_S.1).contains(&frame_time_s) {
        return Err(invalid(
            path,
            time_line,
            None,
            format!(
                "Frame Time {} s is outside {} to {} s (1 to 10000 frames per second)",
                short_number(frame_time_s),
                short_number(FRAME_TIME_S.0),
                short_number(FRAME_TIME_S.1)
            ),
        ));
    }
    check_clip_length(
        (declared - 1) as f64 * frame_time_s,
        format_args!(
            "{}: lines {frames_line}-{time_line}: {declared} frames of {} s",
            path.display(),
            short_number(frame_time_s)
        ),
    )?;
    Ok((declared, frames_line, frame_time_s))
}

/// Frame `frame`'s values (`text`, on `line`) onto `motion`: one finite number per channel,
/// `owners` naming each channel's joint and kind for messages.
fn read_frame(
    text: &str,
    line: usize,
    frame: usize,
    owners: &[(usize, Channel)],
    joints: &[BvhJoint],
    path: &Path,
    motion: &mut Vec<f64>,
) -> Result<(), ImportError> {
    let found = text.split_whitespace().count();
    if found != owners.len() {
        return Err(invalid(
            path,
            line,
            None,
            format!("frame {frame}: expected {} values, found {found}", owners.len()),
        ));
    }
    for (tok, (j, channel)) in text.split_whitespace().zip(owners) {
        let v = parse_finite(tok).ok_or_else(|| {
            invalid(
                path,
                line,
                Some(&joints[*j].name),
                format!("frame {frame}, {}: `{tok}` is not a finite number", channel.name()),
            )
        })?;
        motion.push(v);
    }
    Ok(())
}

/// `Frames: 12` / `Frame Time: 0.05` (any spacing, ASCII case-insensitive key): the value token.
fn header_value<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    let mut rest = line.trim_start();
    for word in key.split_whitespace() {
        let head = rest.get(..word.len())?;
        if !head.eq_ignore_ascii_case(word) {
            return None;
        }
        rest = rest[word.len()..].trim_start();
    }
    let mut value = rest.split_whitespace();
    let v = value.next()?;
    value.next().is_none().then_some(v)
}
