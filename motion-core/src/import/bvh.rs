//! BVH (Biovision hierarchy) motion capture: a general reader ([`Bvh`]), joint maps from common
//! rigs to the 22 joints ([`Rig`]), and [`BvhClip`], which poses a file at any time on the
//! project's canonical skeleton.
//!
//! # Format and conventions
//! - `HIERARCHY`: one `ROOT`, nested `JOINT`s and `End Site`s, each with an `OFFSET` (its
//!   position in the parent's frame, file units) and, for joints, `CHANNELS n ...` with any of
//!   `Xposition Yposition Zposition Xrotation Yrotation Zrotation` in any order, on any joint.
//! - `MOTION`: `Frames: N`, `Frame Time: dt` (seconds), then one line of channel values per frame,
//!   in hierarchy order.
//! - Rotations are Euler angles in degrees, intrinsic in the order written:
//!   `R = R_first · R_second · R_third`. A position channel replaces that component of the
//!   joint's OFFSET (the usual reading for the root, whose OFFSET is normally zero).
//! - A joint's world transform is `parent_world · Translate(offset) · R`.
//! - Axes: Y-up files are right-handed with the character's left at +x when it faces +z, which
//!   are already our axes (CMU/cgspeed, Mixamo exports, Boxing_Toes all are). Z-up files
//!   (character facing −y, left at +x) are turned with `(x, y, z) → (x, z, −y)`.
//! - Units: see [`LengthUnit`]; without one, the unit is detected from the rest skeleton's height.

mod animation;
mod clip;
mod rig;

use std::path::Path;

use glam::DVec3;

pub use animation::BvhAnimation;
pub use clip::{BvhClip, BvhOptions};
pub use rig::Rig;

use super::{check_clip_length, short_number, ImportError, ImportWarning};
use crate::files::read_bytes;
use crate::limits::{MOCAP_FILE_BYTES, RIG_JOINTS};

/// A coordinate axis of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// x.
    X,
    /// y.
    Y,
    /// z.
    Z,
}

/// One channel of a joint: a translation or an Euler rotation (degrees) about a file axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    /// `Xposition`, `Yposition`, `Zposition`.
    Position(Axis),
    /// `Xrotation`, `Yrotation`, `Zrotation`.
    Rotation(Axis),
}

impl Channel {
    /// Parses a channel name (ASCII case-insensitive, as some exporters write `XROTATION`).
    fn from_name(s: &str) -> Option<Channel> {
        let lower = s.to_ascii_lowercase();
        let axis = match lower.as_bytes().first() {
            Some(b'x') => Axis::X,
            Some(b'y') => Axis::Y,
            Some(b'z') => Axis::Z,
            _ => return None,
        };
        match &lower[1..] {
            "position" => Some(Channel::Position(axis)),
            "rotation" => Some(Channel::Rotation(axis)),
            _ => None,
        }
    }

    /// The name as written in files.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Position(Axis::X) => "Xposition",
            Channel::Position(Axis::Y) => "Yposition",
            Channel::Position(Axis::Z) => "Zposition",
            Channel::Rotation(Axis::X) => "Xrotation",
            Channel::Rotation(Axis::Y) => "Yrotation",
            Channel::Rotation(Axis::Z) => "Zrotation",
        }
    }
}

/// A node of the hierarchy: the `ROOT`, a `JOINT`, or an `End Site` (no channels).
#[derive(Debug, Clone, PartialEq)]
pub struct BvhJoint {
    /// The name as written; end sites are called "`<parent>` End Site".
    pub name: String,
    /// Index of the parent node; `None` for the root.
    pub parent: Option<usize>,
    /// Position in the parent's frame, file units and axes.
    pub offset: DVec3,
    /// Channels in the order their values appear on a motion line.
    pub channels: Vec<Channel>,
    /// Whether this is an `End Site`.
    pub end_site: bool,
    /// 1-based line of its `ROOT`/`JOINT`/`End Site` keyword.
    pub line: usize,
}

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

fn invalid(path: &Path, line: usize, joint: Option<&str>, message: impl Into<String>) -> ImportError {
    let location = match joint {
        Some(j) => format!("line {line}, joint {j}"),
        None => format!("line {line}"),
    };
    ImportError::Invalid { path: path.into(), location, message: message.into() }
}

/// Accepted `Frame Time` range, s: 10,000 to 1 frames per second.
const FRAME_TIME_S: (f64, f64) = (1e-4, 1.0);

fn parse_finite(tok: &str) -> Option<f64> {
    tok.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// A hierarchy node while its block is being read.
struct Draft {
    joint: BvhJoint,
    has_offset: bool,
    has_channels: bool,
}

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
    /// refused at its [`RIG_JOINTS`]+1st node; the frame time and the clip's length at 20 fps
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
        let (frames_line, frames_text) =
            rest.next().ok_or_else(|| invalid(path, motion_at + 1, None, "MOTION is not followed by `Frames:`"))?;
        let declared = header_value(frames_text, "Frames:").and_then(|v| v.parse::<usize>().ok()).ok_or_else(|| {
            invalid(path, frames_line, None, format!("expected `Frames: <count>`, found `{}`", frames_text.trim()))
        })?;
        if declared == 0 {
            return Err(ImportError::Empty { path: path.into() });
        }
        let (time_line, time_text) = rest
            .next()
            .ok_or_else(|| invalid(path, frames_line, None, "`Frames:` is not followed by `Frame Time:`"))?;
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
        let owners: Vec<(usize, Channel)> =
            joints.iter().enumerate().flat_map(|(j, joint)| joint.channels.iter().map(move |c| (j, *c))).collect();
        // Every value takes at least two bytes of text, so the file's size bounds the table.
        let mut motion = Vec::with_capacity(declared.saturating_mul(channel_count).min(text.len() / 2));
        let mut frame_lines = Vec::with_capacity(declared.min(text.len() / 2));
        let mut extra_lines = 0;
        for (line, text) in rest {
            let frames = frame_lines.len();
            if frames == declared {
                extra_lines += 1;
                continue;
            }
            let found = text.split_whitespace().count();
            if found != channel_count {
                return Err(invalid(
                    path,
                    line,
                    None,
                    format!("frame {frames}: expected {channel_count} values, found {found}"),
                ));
            }
            for (tok, (j, channel)) in text.split_whitespace().zip(&owners) {
                let v = parse_finite(tok).ok_or_else(|| {
                    invalid(
                        path,
                        line,
                        Some(&joints[*j].name),
                        format!("frame {frames}, {}: `{tok}` is not a finite number", channel.name()),
                    )
                })?;
                motion.push(v);
            }
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

/// Reads the HIERARCHY tokens (each with its 1-based line) without recursion, so deeply nested
/// input cannot overflow the stack.
fn parse_hierarchy<'a>(
    tokens: impl Iterator<Item = (&'a str, usize)>,
    last_line: usize,
    path: &Path,
) -> Result<Vec<BvhJoint>, ImportError> {
    let mut it = tokens.peekable();
    // Checked before each node is added, so a huge hierarchy stops at the first node over.
    let room_for_one_more = |nodes: usize, line: usize| {
        RIG_JOINTS.check(nodes as u64 + 1, format_args!("{}: line {line}: the rig", path.display()))
    };
    match it.next() {
        Some(("HIERARCHY", _)) => {}
        Some((tok, line)) => return Err(invalid(path, line, None, format!("expected HIERARCHY, found `{tok}`"))),
        None => return Err(invalid(path, last_line, None, "expected HIERARCHY")),
    }
    let mut drafts: Vec<Draft> = Vec::new();
    let mut stack: Vec<usize> = Vec::new();
    let mut pending: Option<usize> = None;
    while let Some((tok, line)) = it.next() {
        let current = stack.last().copied();
        let name_of = |i: Option<usize>| i.and_then(|i| drafts.get(i)).map(|d: &Draft| d.joint.name.clone());
        if let Some(p) = pending {
            if tok != "{" {
                return Err(invalid(path, line, name_of(Some(p)).as_deref(), format!("expected `{{`, found `{tok}`")));
            }
        }
        match tok {
            "ROOT" | "JOINT" => {
                if tok == "ROOT" && !drafts.is_empty() {
                    return Err(invalid(path, line, None, "a second ROOT: only one skeleton per file is supported"));
                }
                if tok == "JOINT" && current.is_none() {
                    return Err(invalid(path, line, None, "JOINT outside a joint's braces"));
                }
                if current.is_some_and(|c| drafts[c].joint.end_site) {
                    return Err(invalid(path, line, name_of(current).as_deref(), "an End Site cannot have children"));
                }
                let mut parts = Vec::new();
                while let Some(&(t, l)) = it.peek() {
                    if l != line || t == "{" {
                        break;
                    }
                    parts.push(t);
                    it.next();
                }
                if parts.is_empty() {
                    return Err(invalid(path, line, None, format!("{tok} without a name")));
                }
                room_for_one_more(drafts.len(), line)?;
                pending = Some(drafts.len());
                drafts.push(Draft {
                    joint: BvhJoint {
                        name: parts.join(" "),
                        parent: current,
                        offset: DVec3::ZERO,
                        channels: Vec::new(),
                        end_site: false,
                        line,
                    },
                    has_offset: false,
                    has_channels: false,
                });
            }
            "End" => {
                if !matches!(it.next(), Some(("Site", l)) if l == line) {
                    return Err(invalid(path, line, name_of(current).as_deref(), "expected `End Site`"));
                }
                let Some(parent) = current.filter(|c| !drafts[*c].joint.end_site) else {
                    return Err(invalid(path, line, None, "End Site outside a joint"));
                };
                room_for_one_more(drafts.len(), line)?;
                pending = Some(drafts.len());
                drafts.push(Draft {
                    joint: BvhJoint {
                        name: format!("{} End Site", drafts[parent].joint.name),
                        parent: Some(parent),
                        offset: DVec3::ZERO,
                        channels: Vec::new(),
                        end_site: true,
                        line,
                    },
                    has_offset: false,
                    has_channels: false,
                });
            }
            "{" => match pending.take() {
                Some(i) => stack.push(i),
                None => return Err(invalid(path, line, name_of(current).as_deref(), "unexpected `{`")),
            },
            "}" => {
                let Some(i) = stack.pop() else {
                    return Err(invalid(path, line, None, "unmatched `}`"));
                };
                let d = &drafts[i];
                if !d.has_offset {
                    return Err(invalid(path, d.joint.line, Some(&d.joint.name), "no OFFSET"));
                }
                if !d.joint.end_site && !d.has_channels {
                    return Err(invalid(path, d.joint.line, Some(&d.joint.name), "no CHANNELS line"));
                }
            }
            "OFFSET" => {
                let Some(i) = current else {
                    return Err(invalid(path, line, None, "OFFSET outside a joint"));
                };
                let name = name_of(current);
                if drafts[i].has_offset {
                    return Err(invalid(path, line, name.as_deref(), "a second OFFSET"));
                }
                let mut v = [0.0; 3];
                for (k, slot) in v.iter_mut().enumerate() {
                    let tok = it.next().map_or("end of hierarchy", |(t, _)| t);
                    *slot = parse_finite(tok).ok_or_else(|| {
                        invalid(
                            path,
                            line,
                            name.as_deref(),
                            format!("OFFSET value {k}: `{tok}` is not a finite number"),
                        )
                    })?;
                }
                drafts[i].joint.offset = DVec3::from_array(v);
                drafts[i].has_offset = true;
            }
            "CHANNELS" => {
                let Some(i) = current else {
                    return Err(invalid(path, line, None, "CHANNELS outside a joint"));
                };
                let name = name_of(current);
                if drafts[i].joint.end_site {
                    return Err(invalid(path, line, name.as_deref(), "an End Site cannot have CHANNELS"));
                }
                if drafts[i].has_channels {
                    return Err(invalid(path, line, name.as_deref(), "a second CHANNELS line"));
                }
                let count = it.next().and_then(|(t, _)| t.parse::<usize>().ok()).ok_or_else(|| {
                    invalid(path, line, name.as_deref(), "CHANNELS must be followed by a channel count")
                })?;
                let mut channels = Vec::new();
                while channels.len() < count {
                    match it.peek().and_then(|(t, _)| Channel::from_name(t)) {
                        Some(c) => {
                            channels.push(c);
                            it.next();
                        }
                        None => {
                            return Err(invalid(
                                path,
                                line,
                                name.as_deref(),
                                format!("CHANNELS declares {count} channels but lists {}", channels.len()),
                            ))
                        }
                    }
                }
                drafts[i].joint.channels = channels;
                drafts[i].has_channels = true;
            }
            other => return Err(invalid(path, line, name_of(current).as_deref(), format!("unexpected `{other}`"))),
        }
    }
    if let Some(p) = pending {
        return Err(invalid(path, last_line, Some(&drafts[p].joint.name), "hierarchy ends before its `{`"));
    }
    if let Some(&open) = stack.last() {
        let d = &drafts[open].joint;
        return Err(invalid(
            path,
            last_line,
            Some(&d.name),
            format!("the block opened on line {} is never closed", d.line),
        ));
    }
    if drafts.is_empty() {
        return Err(invalid(path, last_line, None, "the hierarchy has no ROOT"));
    }
    Ok(drafts.into_iter().map(|d| d.joint).collect())
}

/// The length unit of a file's OFFSETs and positions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LengthUnit {
    /// Metres.
    Metres,
    /// Centimetres (Mixamo, most MotionBuilder exports, Boxing_Toes).
    Centimetres,
    /// Millimetres.
    Millimetres,
    /// Inches.
    Inches,
    /// CMU's ASF length unit, 1/0.45 inch = 0.056444 m, kept by the cgspeed BVH conversion.
    CmuAsf,
    /// An explicit scale: metres per file unit (positive).
    MetresPer(f64),
}

/// Stature used to pick a unit: candidates are compared by |ln(height / this)|.
const TYPICAL_STATURE_M: f64 = 1.7;
/// Rest heights outside this range after scaling are reported (m).
const PLAUSIBLE_STATURE_M: (f64, f64) = (1.0, 2.3);

impl LengthUnit {
    /// Units tried by [`LengthUnit::detect`].
    pub const DETECTABLE: [LengthUnit; 5] =
        [LengthUnit::Metres, LengthUnit::Centimetres, LengthUnit::Millimetres, LengthUnit::Inches, LengthUnit::CmuAsf];

    /// Metres per file unit.
    pub fn metres(self) -> f64 {
        match self {
            LengthUnit::Metres => 1.0,
            LengthUnit::Centimetres => 0.01,
            LengthUnit::Millimetres => 0.001,
            LengthUnit::Inches => 0.0254,
            LengthUnit::CmuAsf => 0.0254 / 0.45,
            LengthUnit::MetresPer(m) => m,
        }
    }

    /// The unit of [`LengthUnit::DETECTABLE`] under which a skeleton `rest_height` file units tall
    /// is closest to 1.7 m (by ratio); `None` for a flat or non-finite skeleton. A CMU/cgspeed
    /// skeleton (about 25 units, T-pose with splayed legs) comes out as [`LengthUnit::CmuAsf`].
    pub fn detect(rest_height: f64) -> Option<LengthUnit> {
        if !(rest_height.is_finite() && rest_height > 0.0) {
            return None;
        }
        let miss = |u: &LengthUnit| (rest_height * u.metres() / TYPICAL_STATURE_M).ln().abs();
        LengthUnit::DETECTABLE.into_iter().min_by(|a, b| miss(a).total_cmp(&miss(b)))
    }
}

/// The file's up axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpAxis {
    /// Y up (the BVH norm): axes are used as they are.
    #[default]
    Y,
    /// Z up, character facing −y: `(x, y, z) → (x, z, −y)`.
    Z,
}

impl UpAxis {
    /// A file-axes vector in our axes.
    fn to_ours(self, v: DVec3) -> DVec3 {
        match self {
            UpAxis::Y => v,
            UpAxis::Z => DVec3::new(v.x, v.z, -v.y),
        }
    }
}

#[cfg(test)]
mod tests;
