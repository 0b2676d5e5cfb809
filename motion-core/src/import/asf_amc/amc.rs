//! [`AmcMotion`]: an AMC file's frames on an [`Asf`] skeleton, posed at any time by the
//! Acclaim forward kinematics.

use std::path::Path;
use std::str::SplitWhitespace;

use glam::{DQuat, DVec3};

use super::asf::Asf;
use super::bone::{axis_rotation, euler, Dof};
use super::lines::{invalid, numbered_lines};
use crate::import::error::ImportError;
use crate::import::frames::bracket;
use crate::import::values::{check_clip_length, in_reach, parse_finite, short_number, MAX_POSITION_M};

/// Largest accepted rotation value, degrees (HDM05 writes unwrapped angles past 1000°; beyond
/// this an angle has lost its precision).
const MAX_ROTATION_DEG: f64 = 1e6;

/// The motion of an AMC file: per frame, every bone's dof values (radians and metres) in the
/// ASF's bone and dof order, and the skeleton to pose them on.
#[derive(Debug, Clone)]
pub struct AmcMotion {
    asf: Asf,
    metres_per_unit: f64,
    frame_time_s: f64,
    frames: usize,
    /// Per bone, the index of its first value in a frame row.
    first_value: Vec<usize>,
    /// `[frames, dof_count]`, row-major: rotations in radians, translations and lengths in metres.
    values: Vec<f64>,
    dof_count: usize,
}

impl AmcMotion {
    /// Parses AMC text for the skeleton `asf`; `path` is only used in messages. Lengths are
    /// `metres_per_unit` m per ASF unit; frames are `frame_time_s` apart. The frame count is
    /// checked with [`check_clip_length`] before the frames are stored.
    pub fn parse(
        text: &str,
        path: &Path,
        asf: &Asf,
        metres_per_unit: f64,
        frame_time_s: f64,
    ) -> Result<Self, ImportError> {
        let declared = numbered_lines(text).filter(|(_, l)| is_frame_number(l)).count();
        let last_line = numbered_lines(text).count().max(1);
        if declared == 0 {
            return Err(invalid(path, last_line, None, "the motion has no frames"));
        }
        check_clip_length(
            (declared - 1) as f64 * frame_time_s,
            format_args!("{}: {declared} frames of {} s", path.display(), short_number(frame_time_s)),
        )?;
        let mut reader = AmcReader::new(path, asf, metres_per_unit, declared, text.len());
        for (line, content) in numbered_lines(text) {
            reader.read_line(line, content)?;
        }
        reader.check_frame_complete()?;
        let AmcReader { frames, first_value, values, dof_count, .. } = reader;
        Ok(Self { asf: asf.clone(), metres_per_unit, frame_time_s, frames, first_value, values, dof_count })
    }

    /// The skeleton.
    pub fn asf(&self) -> &Asf {
        &self.asf
    }

    /// Metres per ASF length unit used.
    pub fn metres_per_unit(&self) -> f64 {
        self.metres_per_unit
    }

    /// Number of frames (at least 1).
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Seconds between frames.
    pub fn frame_time_s(&self) -> f64 {
        self.frame_time_s
    }

    /// Time from the first frame to the last, s.
    pub fn duration_s(&self) -> f64 {
        self.frames.saturating_sub(1) as f64 * self.frame_time_s
    }

    /// Start and end of every bone at `t_s` (metres, our axes, in [`Asf::bones`] order; the
    /// root's start and end are its position). Bone rotations are slerped and the root's
    /// translation lerped between the two nearest frames; times outside the clip hold its end
    /// frames.
    pub fn positions_at(&self, t_s: f64) -> Vec<(DVec3, DVec3)> {
        let (k, k1, a) = bracket(t_s, self.frames, self.frame_time_s);
        let locals: Vec<(DQuat, DVec3)> = (0..self.asf.bones().len())
            .map(|b| {
                let ((r0, t0), (r1, t1)) = (self.local(k, b), self.local(k1, b));
                (r0.slerp(r1, a), t0.lerp(t1, a))
            })
            .collect();
        self.forward_kinematics(&locals)
    }

    /// Start and end of every bone in the rest pose (all dofs zero), metres, our axes.
    pub fn rest_positions(&self) -> Vec<(DVec3, DVec3)> {
        self.forward_kinematics(&vec![(DQuat::IDENTITY, DVec3::ZERO); self.asf.bones().len()])
    }

    /// Bone `b`'s rotation at frame `k` in world axes at rest, `C · R · C⁻¹`, and its
    /// translation (metres): the root's AMC translation, or for another bone its `t` dofs in its
    /// local axes plus its `l` dof along its direction.
    fn local(&self, k: usize, b: usize) -> (DQuat, DVec3) {
        let Some(bone) = self.asf.bones().get(b) else { return (DQuat::IDENTITY, DVec3::ZERO) };
        let start = k * self.dof_count + self.first_value.get(b).copied().unwrap_or_default();
        let row = self.values.get(start..).unwrap_or_default();
        let mut angles = [0.0; 3];
        let mut rotation = DQuat::IDENTITY;
        let mut t = DVec3::ZERO;
        let mut l = 0.0;
        for (dof, &v) in bone.dofs.iter().zip(row) {
            match dof {
                Dof::Rotation(axis) => {
                    angles[*axis as usize] = v;
                    rotation = axis_rotation(*axis, v) * rotation;
                }
                Dof::Translation(axis) => t[*axis as usize] = v,
                Dof::Length => l = v,
            }
        }
        if bone.parent.is_none() {
            rotation = euler(&self.asf.root_rotation_order(), angles);
            (bone.axis * rotation * bone.axis.inverse(), t)
        } else {
            (bone.axis * rotation * bone.axis.inverse(), bone.axis * t + bone.direction * l)
        }
    }

    /// Per bone `(rotation, translation)` from [`AmcMotion::local`] → start and end of each bone.
    fn forward_kinematics(&self, locals: &[(DQuat, DVec3)]) -> Vec<(DVec3, DVec3)> {
        let bones = self.asf.bones();
        let root = self.asf.root_position() * self.metres_per_unit;
        let mut out = vec![(root, root); bones.len()];
        let mut world = vec![DQuat::IDENTITY; bones.len()];
        for &b in self.asf.order() {
            let (Some(bone), Some(&(rotation, t))) = (bones.get(b), locals.get(b)) else { continue };
            match bone.parent {
                None => {
                    world[b] = rotation;
                    out[b] = (root + t, root + t);
                }
                Some(p) => {
                    world[b] = world[p] * rotation;
                    let start = out[p].1;
                    let end = start + world[b] * (bone.direction * bone.length * self.metres_per_unit + t);
                    out[b] = (start, end);
                }
            }
        }
        out
    }
}

/// Whether a line holds a frame number alone.
fn is_frame_number(line: &str) -> bool {
    let mut t = line.split_whitespace();
    matches!((t.next().map(str::parse::<u64>), t.next()), (Some(Ok(_)), None))
}

/// An AMC file while it is read line by line: the values so far and the frame being read.
struct AmcReader<'a> {
    /// The file, for messages.
    path: &'a Path,
    asf: &'a Asf,
    /// Metres per ASF length unit.
    metres_per_unit: f64,
    /// Whether angles are in degrees (the ASF's unit, or `:DEGREES`/`:RADIANS`).
    degrees: bool,
    /// Per bone, the index of its first value in a frame row.
    first_value: Vec<usize>,
    dof_count: usize,
    /// `[frames, dof_count]`, row-major, as in [`AmcMotion`].
    values: Vec<f64>,
    /// The frame being read: its number and the line of that number.
    frame: Option<(u64, usize)>,
    /// Which bones the frame being read has had.
    seen: Vec<bool>,
    frames: usize,
}

impl<'a> AmcReader<'a> {
    /// Nothing read yet; room for `declared` frames, bounded by the text's `text_len` bytes.
    fn new(path: &'a Path, asf: &'a Asf, metres_per_unit: f64, declared: usize, text_len: usize) -> Self {
        let bones = asf.bones();
        let mut first_value = Vec::with_capacity(bones.len());
        let mut dof_count = 0;
        for bone in bones {
            first_value.push(dof_count);
            dof_count += bone.dofs.len();
        }
        AmcReader {
            path,
            asf,
            metres_per_unit,
            degrees: asf.degrees(),
            first_value,
            dof_count,
            values: Vec::with_capacity(declared.saturating_mul(dof_count).min(text_len)),
            frame: None,
            seen: vec![false; bones.len()],
            frames: 0,
        }
    }

    /// One line (comment already cut off): a `:` keyword before the first frame, a frame
    /// number, or a bone's values.
    fn read_line(&mut self, line: usize, content: &str) -> Result<(), ImportError> {
        let mut tokens = content.split_whitespace();
        let Some(first) = tokens.next() else { return Ok(()) };
        if let Some(keyword) = first.strip_prefix(':') {
            return self.read_keyword(line, first, keyword);
        }
        if is_frame_number(content) {
            return self.start_frame(line, first.parse::<u64>().unwrap_or_default());
        }
        let Some((number, _)) = self.frame else {
            return Err(invalid(self.path, line, None, format!("expected a frame number, found `{first}`")));
        };
        self.read_bone_values(line, number, first, content, tokens)
    }

    /// `:FULLY-SPECIFIED`, `:DEGREES` or `:RADIANS` (`first` as written), before the first frame.
    fn read_keyword(&mut self, line: usize, first: &str, keyword: &str) -> Result<(), ImportError> {
        if self.frame.is_some() {
            return Err(invalid(self.path, line, None, format!("`{first}` after the first frame")));
        }
        match keyword.to_ascii_uppercase().as_str() {
            "FULLY-SPECIFIED" => {}
            "DEGREES" => self.degrees = true,
            "RADIANS" => self.degrees = false,
            _ => return Err(invalid(self.path, line, None, format!("unknown keyword `{first}`"))),
        }
        Ok(())
    }

    /// A frame number: the frame before it must be complete and numbered one less.
    fn start_frame(&mut self, line: usize, number: u64) -> Result<(), ImportError> {
        self.check_frame_complete()?;
        if let Some((previous, _)) = self.frame {
            if Some(number) != previous.checked_add(1) {
                return Err(invalid(
                    self.path,
                    line,
                    None,
                    format!("frame number {number} out of sequence: expected {}", previous.saturating_add(1)),
                ));
            }
        }
        self.frame = Some((number, line));
        self.seen.iter_mut().for_each(|s| *s = false);
        self.values.resize(self.values.len() + self.dof_count, 0.0);
        self.frames += 1;
        Ok(())
    }

    /// `bone v1 v2 …` (`content`; `first` is the bone, `tokens` the values): one value per dof
    /// of a bone of the ASF, once per frame.
    fn read_bone_values(
        &mut self,
        line: usize,
        number: u64,
        first: &str,
        content: &str,
        tokens: SplitWhitespace<'_>,
    ) -> Result<(), ImportError> {
        let path = self.path;
        let Some(b) = self.asf.bone_index(first) else {
            return Err(invalid(path, line, Some(first), "not defined in the ASF"));
        };
        if std::mem::replace(&mut self.seen[b], true) {
            return Err(invalid(path, line, Some(first), format!("a second line in frame {number}")));
        }
        let bone = &self.asf.bones()[b];
        let found = content.split_whitespace().count() - 1;
        if found != bone.dofs.len() {
            let names: Vec<&str> = bone.dofs.iter().map(|d| d.name()).collect();
            return Err(invalid(
                path,
                line,
                Some(first),
                format!("frame {number}: expected {} values ({}), found {found}", bone.dofs.len(), names.join(" ")),
            ));
        }
        let row = (self.frames - 1) * self.dof_count + self.first_value[b];
        for (k, (tok, dof)) in tokens.zip(&bone.dofs).enumerate() {
            let at = |what: String| invalid(path, line, Some(first), format!("frame {number}, {}: {what}", dof.name()));
            let v = parse_finite(tok).ok_or_else(|| at(format!("`{tok}` is not a finite number")))?;
            let converted = self.convert(*dof, v, &at)?;
            if let Some(slot) = self.values.get_mut(row + k) {
                *slot = converted;
            }
        }
        Ok(())
    }

    /// A dof's value as written → radians (a rotation, within [`MAX_ROTATION_DEG`]) or metres
    /// (a translation or length, within [`MAX_POSITION_M`] of the origin).
    fn convert(&self, dof: Dof, v: f64, at: &dyn Fn(String) -> ImportError) -> Result<f64, ImportError> {
        match dof {
            Dof::Rotation(_) => {
                let deg = if self.degrees { v } else { v.to_degrees() };
                if deg.abs() > MAX_ROTATION_DEG {
                    return Err(at(format!(
                        "{} degrees is out of range (beyond ±{} degrees)",
                        short_number(deg),
                        short_number(MAX_ROTATION_DEG)
                    )));
                }
                Ok(deg.to_radians())
            }
            Dof::Translation(_) | Dof::Length => {
                let m = v * self.metres_per_unit;
                if !in_reach(m) {
                    return Err(at(format!(
                        "{} ({} m) is out of range (more than {} m from the origin)",
                        short_number(v),
                        short_number(m),
                        short_number(MAX_POSITION_M)
                    )));
                }
                Ok(m)
            }
        }
    }

    /// The frame being read, if any, must have had every bone with dofs.
    fn check_frame_complete(&self) -> Result<(), ImportError> {
        let Some((number, line)) = self.frame else { return Ok(()) };
        let missing: Vec<&str> = self
            .asf
            .bones()
            .iter()
            .zip(&self.seen)
            .filter(|(b, s)| !b.dofs.is_empty() && !**s)
            .map(|(b, _)| b.name.as_str())
            .collect();
        if missing.is_empty() {
            Ok(())
        } else {
            Err(invalid(self.path, line, None, format!("frame {number} lacks bones: {}", missing.join(", "))))
        }
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_1_SQRT_2;

    use super::*;
    use crate::import::asf_amc::tests::{edit, parse_tiny, TINY_AMC, TINY_ASF};
    use crate::import::bvh::Axis;

    fn close(got: &[(DVec3, DVec3)], want: &[[f64; 3]]) -> bool {
        got.len() == want.len()
            && got.iter().zip(want).all(|((_, end), w)| (*end - DVec3::from_array(*w)).length() < 1e-12)
    }

    #[test]
    fn euler_angles_apply_about_fixed_axes_in_the_written_order() {
        let q = |order: &str| {
            let axes: Vec<Axis> = order
                .bytes()
                .map(|c| match c {
                    b'X' => Axis::X,
                    b'Y' => Axis::Y,
                    _ => Axis::Z,
                })
                .collect();
            euler(&axes, [90f64.to_radians(), 90f64.to_radians(), 0.0])
        };
        // XYZ: x stays under R_x, then R_y takes it to −z. ZYX: R_y first (x → −z), then R_x
        // (−z → +y).
        assert!((q("XYZ") * DVec3::X - DVec3::NEG_Z).length() < 1e-12);
        assert!((q("ZYX") * DVec3::X - DVec3::Y).length() < 1e-12);
    }

    #[test]
    fn two_bone_chain_gives_hand_computed_positions() {
        let (m, _) = parse_tiny(TINY_ASF, TINY_AMC).unwrap();
        let u = 0.0254 / 0.5;
        assert_eq!(m.frames(), 2);
        assert!((m.duration_s() - 1.0 / 120.0).abs() < 1e-15);
        // Frame 1 is the rest pose: upper along +x (2 units), lower along +y (1 unit).
        let rest = [[0.0; 3], [2.0 * u, 0.0, 0.0], [2.0 * u, u, 0.0]];
        assert!(close(&m.positions_at(0.0), &rest));
        assert!(close(&m.rest_positions(), &rest));
        // Frame 2: the root moves to (10, 20, 30) units and turns 90° about y. upper's rx 90 is
        // about its local x, which its axis (0 0 90) turns to world +y: C·R_x(90)·C⁻¹ = R_y(90),
        // so upper points along R_y(180)·x = −x. lower's rx 90 turns +y to +z, then R_y(180)
        // takes +z to −z.
        let root = [10.0 * u, 20.0 * u, 30.0 * u];
        let upper = [root[0] - 2.0 * u, root[1], root[2]];
        let lower = [upper[0], upper[1], upper[2] - u];
        assert!(close(&m.positions_at(1.0 / 120.0), &[root, upper, lower]));
        assert_eq!(m.positions_at(1.0 / 120.0)[2].0, m.positions_at(1.0 / 120.0)[1].1);
        // Half way: the root lerped, every rotation slerped to 45°: upper's world rotation is
        // R_y(90) (x → −z), lower's R_y(90)·R_x(45) takes y to (h, h, 0).
        let h = FRAC_1_SQRT_2;
        let root = [5.0 * u, 10.0 * u, 15.0 * u];
        let upper = [root[0], root[1], root[2] - 2.0 * u];
        let lower = [upper[0] + h * u, upper[1] + h * u, upper[2]];
        assert!(close(&m.positions_at(0.5 / 120.0), &[root, upper, lower]));
        // Outside the clip the end frames hold.
        assert!(close(&m.positions_at(-1.0), &rest));
        assert!(close(&m.positions_at(f64::NAN), &rest));
    }

    #[test]
    fn radians_root_order_orientation_and_translation_dofs() {
        // The same motion in radians, with the root's values written rotations first.
        let asf = TINY_ASF.replace("order TX TY TZ RX RY RZ", "order RX RY RZ TX TY TZ");
        let r = std::f64::consts::FRAC_PI_2;
        let amc = TINY_AMC
            .replace(":DEGREES", ":RADIANS")
            .replace("root 10 20 30 0 90 0", &format!("root 0 {r} 0 10 20 30"))
            .replace("upper 90 0 0", &format!("upper {r} 0 0"))
            .replace("lower 90", &format!("lower {r}"));
        let (a, _) = parse_tiny(TINY_ASF, TINY_AMC).unwrap();
        let (b, _) = parse_tiny(&asf, &amc).unwrap();
        assert!(close(&b.positions_at(1.0), &a.positions_at(1.0).iter().map(|p| p.1.to_array()).collect::<Vec<_>>()));
        // A translation dof moves a bone's end along its local axes; `l` lengthens it.
        let asf = edit(TINY_ASF, 33, Some("dof rx tx l"));
        let amc = TINY_AMC.replace("lower 0", "lower 0 1 2").replace("lower 90", "lower 0 0 0");
        let (m, _) = parse_tiny(&asf, &amc).unwrap();
        let u = 0.0254 / 0.5;
        assert!(close(&m.positions_at(0.0), &[[0.0; 3], [2.0 * u, 0.0, 0.0], [3.0 * u, 3.0 * u, 0.0]]));
        // The root's orientation turns the axes its rotation is about: with orientation 0 0 90,
        // the root's ry 90 is about world −x (Rz90·y), which keeps upper along +x and turns
        // lower's +y to −z.
        let asf = edit(TINY_ASF, 14, Some("orientation 0 0 90"));
        let (m, _) =
            parse_tiny(&asf, &TINY_AMC.replace("upper 90 0 0", "upper 0 0 0").replace("lower 90", "lower 0")).unwrap();
        let p = m.positions_at(1.0);
        assert!(((p[1].1 - p[1].0) / (2.0 * u) - DVec3::X).length() < 1e-12);
        assert!(((p[2].1 - p[2].0) / u - DVec3::NEG_Z).length() < 1e-12, "{:?}", p[2].1 - p[2].0);
    }
}
