//! Acclaim ASF/AMC motion capture (CMU, HDM05): the skeleton file ([`Asf`]), its motion
//! ([`AmcMotion`], posed by forward kinematics at any time), and [`AsfAmcClip`], which poses a
//! pair of files at any time on the project's canonical skeleton.
//!
//! # Format and conventions
//! - ASF: `:units` (`length` is a scale: metres = value / length × 0.0254, so CMU's and HDM05's
//!   `length 0.45` makes a unit 1/0.45 inch; `angle deg|rad`), `:root` (`order`: the AMC value
//!   order of the root, `axis`: its rotation order, `position`, `orientation`), `:bonedata`
//!   (`begin` … `end` blocks with `name`, `direction` (unit vector, world axes at rest),
//!   `length`, `axis ax ay az ORDER`, `dof` and `limits`) and `:hierarchy` (`parent child…`).
//! - AMC: optional `:FULLY-SPECIFIED`, `:DEGREES` or `:RADIANS` (default: the ASF's angle unit),
//!   then per frame its number (consecutive) and one line per bone with dofs, values in the
//!   bone's `dof` order. The frame rate is not in the files (120 fps for CMU and HDM05).
//! - Euler angles are applied in the order written about fixed axes, the first first: `axis
//!   0 0 20 XYZ` is `C = R_z · R_y · R_x`, and a bone's `rx ry rz` values give `R = R_z · R_y ·
//!   R_x` (as the CMU player does). The root's rotation follows the root `axis` order.
//! - Forward kinematics (the Acclaim way): a bone's world rotation is `M = M_parent · C · R ·
//!   C⁻¹` (the root's `C` is its `orientation`), it starts at its parent's end (the root's is
//!   `position` + the AMC translation) and ends at `start + M · direction · length`.
//! - Axes: y up and right-handed; the rest skeleton of CMU and HDM05 has its left leg at +x
//!   and its toes at +z, which are already our axes, so coordinates are used as they are.

mod amc;
mod asf;
mod bone;
mod clip;
mod lines;

pub use amc::AmcMotion;
pub use asf::Asf;
pub use bone::{AsfBone, Dof};
pub use clip::{AsfAmcClip, AsfAmcOptions};

#[cfg(test)]
pub(super) mod tests {
    use glam::DVec3;

    use std::path::Path;

    use super::*;
    use crate::import::{ImportError, ImportWarning};

    /// A root and a two-bone chain, lengths in units of 1/0.5 inch (0.0508 m); the tests refer to
    /// its 1-based line numbers.
    pub(crate) const TINY_ASF: &str = "# a root and a two-bone chain
:version 1.10
:name TINY
:units
  mass 1.0
  length 0.5
  angle deg
:documentation
  free text, ignored
:root
  order TX TY TZ RX RY RZ
  axis XYZ
  position 0 0 0
  orientation 0 0 0
:bonedata
  begin
    id 1
    name upper
    direction 1 0 0
    length 2
    axis 0 0 90 XYZ
    dof rx ry rz
    limits (-180 180)
           (-180 180)
           (-180 180)
  end
  begin
    id 2
    name lower
    direction 0 1 0
    length 1
    axis 0 0 0 XYZ
    dof rx
    limits (-10 170)
  end
:hierarchy
  begin
    root upper
    upper lower
  end
";

    /// Two frames of [`TINY_ASF`]: rest, then moved and turned.
    pub(crate) const TINY_AMC: &str = ":FULLY-SPECIFIED
:DEGREES
1
root 0 0 0 0 0 0
upper 0 0 0
lower 0
2
root 10 20 30 0 90 0
upper 90 0 0
lower 90
";

    /// `text` with 1-based line `n` replaced (or removed when `None`).
    pub(crate) fn edit(text: &str, n: usize, with: Option<&str>) -> String {
        let mut lines: Vec<&str> = text.lines().collect();
        match with {
            Some(w) => lines[n - 1] = w,
            None => {
                lines.remove(n - 1);
            }
        }
        lines.join("\n") + "\n"
    }

    pub(crate) fn parse_tiny(asf: &str, amc: &str) -> Result<(AmcMotion, Vec<ImportWarning>), ImportError> {
        let (skeleton, warnings) = Asf::parse(asf, Path::new("tiny.asf"))?;
        let motion = AmcMotion::parse(amc, Path::new("tiny.amc"), &skeleton, skeleton.metres_per_unit(), 1.0 / 120.0)?;
        Ok((motion, warnings))
    }

    fn err(asf: &str, amc: &str) -> String {
        parse_tiny(asf, amc).map(|_| ()).unwrap_err().to_string()
    }

    #[test]
    fn reads_units_root_bones_dofs_and_hierarchy() {
        let (asf, warnings) = Asf::parse(TINY_ASF, Path::new("tiny.asf")).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        let names: Vec<&str> = asf.bones().iter().map(|b| b.name.as_str()).collect();
        assert_eq!(names, ["root", "upper", "lower"]);
        assert_eq!(asf.bones()[2].parent, Some(1));
        assert_eq!(asf.bones()[1].line, 16);
        assert_eq!(asf.bones()[2].dofs, [Dof::Rotation(crate::import::bvh::Axis::X)]);
        assert_eq!(asf.bones()[0].dofs.len(), 6);
        assert_eq!(asf.order(), [0, 1, 2]);
        assert!((asf.metres_per_unit() - 0.0508).abs() < 1e-12 && asf.degrees());
        // Rest: upper along +x for 2 units, lower along +y for 1.
        let rest = asf.rest_positions();
        assert_eq!(rest[2], (DVec3::new(2.0, 0.0, 0.0), DVec3::new(2.0, 1.0, 0.0)));
        // Without `length`, inches are assumed and said so.
        let (inches, warnings) = Asf::parse(&edit(TINY_ASF, 6, None), Path::new("tiny.asf")).unwrap();
        assert!((inches.metres_per_unit() - 0.0254).abs() < 1e-12);
        assert!(warnings.len() == 1 && warnings[0].message.contains("inches"), "{warnings:?}");
    }

    #[test]
    fn bad_inputs_name_the_file_and_line() {
        let asf_cases: Vec<(String, &str, &str)> = vec![
            (edit(TINY_ASF, 4, Some(":unitz")), "line 4", "unknown keyword `:unitz`"),
            (TINY_ASF.lines().take(14).collect::<Vec<_>>().join("\n"), "line 14", "missing `:bonedata`"),
            (TINY_ASF.lines().take(35).collect::<Vec<_>>().join("\n"), "line 35", "missing `:hierarchy`"),
            (edit(TINY_ASF, 39, Some("upper lowr")), "line 39, bone lowr", "not defined in `:bonedata`"),
            (edit(TINY_ASF, 38, Some("rooot upper")), "line 38, bone rooot", "not defined in `:bonedata`"),
            (edit(TINY_ASF, 20, Some("length abc")), "line 20, bone upper", "length value 0: `abc` is not a finite"),
            (edit(TINY_ASF, 20, Some("length inf")), "line 20, bone upper", "not a finite number"),
            (edit(TINY_ASF, 19, Some("direction 1 nan 0")), "line 19, bone upper", "direction value 1"),
            (edit(TINY_ASF, 19, Some("direction 0 0 0")), "line 19, bone upper", "direction is zero"),
            (edit(TINY_ASF, 19, Some("direction 1 0")), "line 19, bone upper", "direction value 2"),
            (edit(TINY_ASF, 21, Some("axis 0 0 90 XYQ")), "line 21, bone upper", "unknown rotation order `XYQ`"),
            (edit(TINY_ASF, 21, Some("axis 0 0 90 XXY")), "line 21, bone upper", "unknown rotation order `XXY`"),
            (edit(TINY_ASF, 12, Some("axis ZYZ")), "line 12", "unknown rotation order `ZYZ`"),
            (edit(TINY_ASF, 11, Some("order TX TY TZ RX RY RQ")), "line 11", "`RQ` is not one of"),
            (edit(TINY_ASF, 22, Some("dof rx rw")), "line 22, bone upper", "unknown dof `rw`"),
            (edit(TINY_ASF, 22, Some("dof rx rx")), "line 22, bone upper", "dof `rx` listed twice"),
            (edit(TINY_ASF, 22, Some("colour red")), "line 22, bone upper", "unknown bone field `colour`"),
            (edit(TINY_ASF, 7, Some("angle grad")), "line 7", "angle unit must be deg or rad"),
            (edit(TINY_ASF, 6, Some("length 0")), "line 6", "length scale 0 is not positive"),
            (edit(TINY_ASF, 5, Some("weight 1")), "line 5", "unknown unit `weight`"),
            (edit(TINY_ASF, 26, None), "line 26, bone upper", "`begin` inside a bone; is an `end` missing?"),
            (edit(TINY_ASF, 35, None), "line 27, bone lower", "`begin` without `end`"),
            (edit(TINY_ASF, 18, None), "line 16", "bone without `name`"),
            (edit(TINY_ASF, 20, None), "line 16, bone upper", "no `length`"),
            (edit(TINY_ASF, 29, Some("name upper")), "line 27, bone upper", "a second bone of this name"),
            (edit(TINY_ASF, 39, Some("upper lower\n  root lower")), "line 40, bone lower", "a second parent: root"),
            (edit(TINY_ASF, 38, Some("lower upper")), "line 38, bone upper", "cycle"),
            (edit(TINY_ASF, 39, Some("upper root")), "line 39, bone root", "the root cannot be a child"),
            (edit(TINY_ASF, 39, None), "line 27, bone lower", "not in the `:hierarchy`"),
            (edit(TINY_ASF, 40, None), "line 39", "no `begin` … `end`"),
            (edit(TINY_ASF, 2, Some("version 1.10")), "line 2", "expected a `:` keyword"),
            (edit(TINY_ASF, 16, Some("bgin")), "line 16", "expected `begin`, found `bgin`"),
            (edit(TINY_ASF, 15, Some(":root")), "line 15", "a second `:root`"),
        ];
        for (asf, place, what) in asf_cases {
            let e = err(&asf, TINY_AMC);
            assert!(e.starts_with("tiny.asf: "), "{e}");
            assert!(e.contains(place) && e.contains(what), "expected `{place}` and `{what}` in: {e}");
        }
        let amc_cases: Vec<(String, &str, &str)> = vec![
            (edit(TINY_AMC, 1, Some(":SPEED 120")), "line 1", "unknown keyword `:SPEED`"),
            (edit(TINY_AMC, 6, Some("lowr 0")), "line 6, bone lowr", "not defined in the ASF"),
            (
                edit(TINY_AMC, 5, Some("upper 0 0")),
                "line 5, bone upper",
                "frame 1: expected 3 values (rx ry rz), found 2",
            ),
            (edit(TINY_AMC, 10, Some("lower 90 0")), "line 10, bone lower", "frame 2: expected 1 values (rx), found 2"),
            (edit(TINY_AMC, 9, Some("upper 90 x 0")), "line 9, bone upper", "frame 2, ry: `x` is not a finite number"),
            (edit(TINY_AMC, 9, Some("upper nan 0 0")), "line 9, bone upper", "frame 2, rx: `nan` is not a finite"),
            (edit(TINY_AMC, 8, Some("root 1 2 inf 0 0 0")), "line 8, bone root", "frame 2, tz: `inf`"),
            (edit(TINY_AMC, 8, Some("root 1 2 1e300 0 0 0")), "line 8, bone root", "frame 2, tz: 1e300"),
            (edit(TINY_AMC, 9, Some("upper 2e7 0 0")), "line 9, bone upper", "2e7 degrees is out of range"),
            (edit(TINY_AMC, 7, Some("3")), "line 7", "frame number 3 out of sequence: expected 2"),
            (edit(TINY_AMC, 7, Some("1")), "line 7", "frame number 1 out of sequence"),
            (":FULLY-SPECIFIED\n:DEGREES\n".into(), "line 2", "the motion has no frames"),
            (String::new(), "line 1", "the motion has no frames"),
            (edit(TINY_AMC, 6, None), "line 3", "frame 1 lacks bones: lower"),
            (edit(TINY_AMC, 10, Some("upper 0 0 0")), "line 10, bone upper", "a second line in frame 2"),
            (edit(TINY_AMC, 3, Some("root 0 0 0 0 0 0")), "line 3", "expected a frame number, found `root`"),
            (TINY_AMC.to_owned() + ":DEGREES\n", "line 11", "`:DEGREES` after the first frame"),
        ];
        for (amc, place, what) in amc_cases {
            let e = err(TINY_ASF, &amc);
            assert!(e.starts_with("tiny.amc: "), "{e}");
            assert!(e.contains(place) && e.contains(what), "expected `{place}` and `{what}` in: {e}");
        }
    }

    #[test]
    fn clip_lengths_are_checked_before_the_frames_are_stored() {
        // 100 000 frame numbers at 1 fps is 27.8 hours: refused from the count alone.
        let mut amc = String::new();
        for k in 1..=100_000 {
            amc.push_str(&format!("{k}\n"));
        }
        let (asf, _) = Asf::parse(TINY_ASF, Path::new("tiny.asf")).unwrap();
        let e = AmcMotion::parse(&amc, Path::new("long.amc"), &asf, 0.05, 1.0).unwrap_err().to_string();
        assert!(e.starts_with("long.amc: 100000 frames of 1 s"), "{e}");
        assert!(e.contains("imported clip length"), "{e}");
    }

    #[test]
    fn truncated_or_mutated_files_give_errors_not_panics() {
        for cut in 0..TINY_ASF.len() {
            let _ = parse_tiny(&TINY_ASF[..cut], TINY_AMC);
        }
        for cut in 0..TINY_AMC.len() {
            let _ = parse_tiny(TINY_ASF, &TINY_AMC[..cut]);
        }
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let junk = ["begin", "end", ":root", "x", "-", "1e999", " ", "\n", "root", "upper", "nan", "\u{e9}", "#", "7"];
        for _ in 0..600 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let (text, is_asf) = if state & 1 == 0 { (TINY_ASF, true) } else { (TINY_AMC, false) };
            let at = (state >> 8) as usize % text.len();
            let mutated = format!("{}{}{}", &text[..at], junk[(state >> 40) as usize % junk.len()], &text[at + 1..]);
            let (asf, amc) = if is_asf { (mutated.as_str(), TINY_AMC) } else { (TINY_ASF, mutated.as_str()) };
            if let Ok((motion, _)) = parse_tiny(asf, amc) {
                let _ = motion.positions_at(0.003);
            }
        }
    }
}
