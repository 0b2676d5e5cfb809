//! The BVH reader against hand-written files: hierarchy, channels, units, axes, and every
//! malformed input an error naming the line.

use std::path::Path;

use super::*;
use crate::import::{ImportError, ImportWarning};
use crate::limits::RIG_JOINTS;

/// A root with a one-bone arm along +x; the tests refer to its 1-based line numbers.
pub(super) const TINY: &str = "HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Arm
  {
    OFFSET 1 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 1 0 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
0 0 0 0 0 0 0 0 0
1 2 3 90 0 0 0 0 90
";

/// TINY with 1-based line `n` replaced (or removed when `None`).
pub(super) fn edit(n: usize, with: Option<&str>) -> String {
    let mut lines: Vec<&str> = TINY.lines().collect();
    match with {
        Some(w) => lines[n - 1] = w,
        None => {
            lines.remove(n - 1);
        }
    }
    lines.join("\n") + "\n"
}

fn parse(text: &str) -> Result<(Bvh, Vec<ImportWarning>), ImportError> {
    Bvh::parse(text, Path::new("tiny.bvh"))
}

fn err(text: &str) -> String {
    parse(text).map(|_| ()).unwrap_err().to_string()
}

#[test]
fn reads_hierarchy_channels_and_motion() {
    let (bvh, warnings) = parse(TINY).unwrap();
    assert!(warnings.is_empty());
    let names: Vec<_> = bvh.joints().iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["Hips", "Arm", "Arm End Site"]);
    assert_eq!(bvh.joints()[1].parent, Some(0));
    assert_eq!(bvh.joints()[1].line, 6);
    assert!(bvh.joints()[2].end_site);
    assert_eq!(bvh.joints()[0].channels[3], Channel::Rotation(Axis::Z));
    assert_eq!(
        bvh.joints()[1].channels,
        [Channel::Rotation(Axis::Z), Channel::Rotation(Axis::X), Channel::Rotation(Axis::Y)]
    );
    assert_eq!((bvh.frames(), bvh.frame_time_s()), (2, 0.5));
    assert_eq!(bvh.frame(1).unwrap()[8], 90.0);
    assert!(bvh.frame(2).is_none() && bvh.frame(usize::MAX).is_none());
    assert_eq!(bvh.joint_index("arm"), Some(1));
    assert_eq!(bvh.joint_index("Arm End Site"), None);
    assert_eq!(bvh.rest_height(UpAxis::Y), 0.0);
    assert_eq!(bvh.rest_height(UpAxis::Z), 0.0);
}

#[test]
fn tolerates_spacing_case_crlf_and_trailing_lines() {
    let text = TINY
        .replace("Frames: 2", "Frames:2")
        .replace("Frame Time: 0.5", "Frame   Time:\t.5")
        .replace("Zrotation Xrotation Yrotation\n    End", "ZROTATION xrotation Yrotation\n    End")
        .replace('\n', "\r\n")
        + "\r\n0 0 0 0 0 0 0 0 0\r\n";
    let (bvh, warnings) = parse(&text).unwrap();
    assert_eq!((bvh.frames(), bvh.frame_time_s()), (2, 0.5));
    assert_eq!(warnings.len(), 1);
    assert!(warnings[0].message.contains("ignored 1 lines"));
}

#[test]
fn bad_inputs_name_the_line() {
    let cases: Vec<(String, &str, &str)> = vec![
        (edit(9, Some("CHANNELS 3 Zrotation Xrotation")), "line 9, joint Arm", "declares 3 channels but lists 2"),
        (edit(9, Some("CHANNELS")), "line 9, joint Arm", "channel count"),
        (edit(9, None), "line 6, joint Arm", "no CHANNELS"),
        (edit(8, None), "line 6, joint Arm", "no OFFSET"),
        (edit(8, Some("OFFSET 1 x 0")), "line 8, joint Arm", "`x` is not a finite number"),
        (edit(8, Some("OFFSET 1 0")), "line 8, joint Arm", "OFFSET value 2"),
        (edit(20, Some("1 2 3 90 0 0 0 abc 90")), "line 20, joint Arm", "frame 1, Xrotation: `abc`"),
        (edit(20, Some("1 2 3 90 0 0 0 0")), "line 20", "expected 9 values, found 8"),
        (edit(19, Some("0 0 0 0 0 0 0 0 0 0")), "line 19", "expected 9 values, found 10"),
        (edit(17, Some("Frames: 3")), "line 20", "after 2 of the 3 frames declared on line 17"),
        (edit(17, Some("Frames: lots")), "line 17", "Frames:"),
        (edit(17, Some("Frame: 2")), "line 17", "Frames:"),
        (edit(18, Some("Frame Time: 0")), "line 18", "Frame Time 0 s is outside 0.0001 to 1 s"),
        (edit(18, Some("Frame Time: -0.1")), "line 18", "Frame Time -0.1 s is outside"),
        (edit(18, Some("Frame Time: nan")), "line 18", "Frame Time"),
        (edit(20, Some("1 2 NaN 90 0 0 0 0 90")), "line 20, joint Hips", "frame 1, Zposition: `NaN`"),
        (edit(20, Some("1 2 3 inf 0 0 0 0 90")), "line 20, joint Hips", "not a finite number"),
        (edit(19, Some("0 0 0 0 0 0 0 0 -infinity")), "line 19, joint Arm", "not a finite number"),
        (edit(8, Some("OFFSET 1 nan 0")), "line 8, joint Arm", "not a finite number"),
        (String::new(), "line 1", "empty file"),
        (" \n\n\t\n".into(), "line 1", "empty file"),
        (TINY.lines().take(15).collect::<Vec<_>>().join("\n"), "line 15", "without a MOTION section"),
        (TINY.lines().take(16).collect::<Vec<_>>().join("\n"), "line 16", "not followed by `Frames:`"),
        (TINY.lines().take(17).collect::<Vec<_>>().join("\n"), "line 17", "not followed by `Frame Time:`"),
        (edit(1, Some("HIERARCH")), "line 1", "expected HIERARCHY"),
        (edit(15, None), "line 14, joint Hips", "block opened on line 2 is never closed"),
        (edit(3, None), "line 3, joint Hips", "expected `{`, found `OFFSET`"),
        (edit(6, Some("JOINT")), "line 6", "JOINT without a name"),
        (edit(10, Some("End Zone")), "line 10, joint Arm", "expected `End Site`"),
        (edit(12, Some("CHANNELS 1 Xrotation")), "line 12, joint Arm End Site", "cannot have CHANNELS"),
        (edit(12, Some("JOINT Hand")), "line 12, joint Arm End Site", "cannot have children"),
        (
            edit(9, Some("CHANNELS 3 Zrotation Xrotation Yrotation OFFSET 0 0 0")),
            "line 9, joint Arm",
            "a second OFFSET",
        ),
        (edit(9, Some("CHANNELS 3 Zrotation Xrotation Wrotation")), "line 9, joint Arm", "lists 2"),
        (edit(15, Some("} }")), "line 15", "unmatched `}`"),
        (edit(15, Some("} ROOT Other {")), "line 15", "a second ROOT"),
        (edit(4, Some("OFFSET 0 0 0 0")), "line 4, joint Hips", "unexpected `0`"),
    ];
    for (text, place, what) in cases {
        let e = err(&text);
        assert!(e.starts_with("tiny.bvh: "), "{e}");
        assert!(e.contains(place) && e.contains(what), "expected `{place}` and `{what}` in: {e}");
    }
    assert!(matches!(parse(&edit(17, Some("Frames: 0"))), Err(ImportError::Empty { .. })));
    let no_channels = TINY
        .replace("CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation", "CHANNELS 0")
        .replace("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 0");
    assert!(err(&no_channels).contains("line 2") && err(&no_channels).contains("no channels"));
}

#[test]
fn truncated_or_mutated_files_give_errors_not_panics() {
    let last_line_start = TINY.trim_end().rfind('\n').unwrap() + 1;
    for cut in 0..TINY.len() {
        let r = parse(&TINY[..cut]);
        if cut < last_line_start {
            assert!(r.is_err(), "cut at byte {cut} parsed");
        }
    }
    // A real header with three frames, cut every 50th byte and mutated byte by byte.
    let real = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/cmu/cmu_01_01_20fps.bvh"),
    )
    .unwrap();
    let motion = real.find("MOTION").unwrap();
    let frames: Vec<&str> = real[motion..].lines().skip(3).take(3).collect();
    let small = format!("{}MOTION\nFrames: 3\nFrame Time: 0.05\n{}\n", &real[..motion], frames.join("\n"));
    let last_start = small.trim_end().rfind('\n').unwrap() + 1;
    let options = BvhOptions::default();
    for cut in (0..small.len()).step_by(50) {
        let r = parse(&small[..cut]);
        assert!(cut >= last_start || r.is_err(), "cut at byte {cut} parsed");
    }
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let junk = ["{", "}", "x", "-", "1e999", " ", "\n", "JOINT", "End", "CHANNELS 9", "nan", "\u{e9}"];
    for _ in 0..400 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let at = (state as usize) % small.len();
        let at = (0..=at).rev().find(|i| small.is_char_boundary(*i)).unwrap_or(0);
        let mutated = format!(
            "{}{}{}",
            &small[..at],
            junk[(state >> 40) as usize % junk.len()],
            &small[(at + 1).min(small.len())..]
        );
        if let Ok((bvh, _)) = parse(&mutated) {
            if let Ok((clip, _)) = BvhClip::from_bvh("m", &bvh, &options, Path::new("m.bvh")) {
                use crate::import::MocapClip;
                let _ = clip.pose_at(0.07);
            }
        }
    }
    assert!(err("\u{0}\u{1}\u{ff}").contains("line 1"));
    assert!(err(&edit(9, Some("CHANNELS 18446744073709551615 Xrotation"))).contains("lists 1"));
}

#[test]
fn deep_nesting_does_not_overflow_the_stack() {
    let chain = |depth: usize| {
        let mut text = String::from("HIERARCHY\nROOT J0\n{\nOFFSET 0 1 0\nCHANNELS 1 Zrotation\n");
        for i in 1..depth {
            text.push_str(&format!("JOINT J{i}\n{{\nOFFSET 0 1 0\nCHANNELS 1 Zrotation\n"));
        }
        text.push_str(&"}\n".repeat(depth));
        text + &format!("MOTION\nFrames: 1\nFrame Time: 0.1\n{}\n", vec!["1"; depth].join(" "))
    };
    let depth = RIG_JOINTS.max_usize();
    let (bvh, _) = parse(&chain(depth)).unwrap();
    assert_eq!(bvh.joints().len(), depth);
    assert_eq!(bvh.rest_height(UpAxis::Y), (depth - 1) as f64);
    let e = BvhClip::from_bvh("deep", &bvh, &BvhOptions::default(), Path::new("deep.bvh")).unwrap_err();
    assert!(e.to_string().contains("no known rig"));
    assert!(err(&chain(20_000)).contains("joints per rig"));
}

#[test]
fn frame_times_and_clip_lengths_are_checked_before_the_motion_is_read() {
    for (time, shown) in [("100000", "100000"), ("0.00000001", "1e-8"), ("-1e308", "-1e308")] {
        let e = err(&edit(18, Some(&format!("Frame Time: {time}"))));
        assert!(e.starts_with("tiny.bvh: line 18") && e.contains(shown), "{e}");
        assert!(e.len() < 300, "{e}");
    }
    // 200000 frames half a second apart: 99999.5 s, 1999991 frames at 20 fps.
    let e = err(&edit(17, Some("Frames: 200000")));
    assert!(e.starts_with("tiny.bvh: lines 17-18"), "{e}");
    assert!(e.contains("is 1999991 frames at 20 fps, over the limit of 72000 frames at 20 fps"), "{e}");
    assert!(e.contains("(imported clip length)"), "{e}");
    assert!(err(&edit(17, Some("Frames: 18446744073709551615"))).contains("imported clip length"));
}

/// A root with `joints` zero-channel children, one frame.
fn wide(joints: usize) -> String {
    let mut text = String::from("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 1 Xposition\n");
    for j in 0..joints {
        text.push_str(&format!("JOINT J{j}\n{{\nOFFSET 0 1 0\nCHANNELS 0\n}}\n"));
    }
    text + "}\nMOTION\nFrames: 1\nFrame Time: 0.05\n0\n"
}

#[test]
fn rigs_over_the_joint_limit_are_refused_while_parsing() {
    let (bvh, _) = parse(&wide(1023)).unwrap();
    assert_eq!(bvh.joints().len(), 1024);
    // The root is node 1, J1023 node 1025, on line 6 + 5 · 1023.
    let e = err(&wide(100_000));
    assert!(e.starts_with("tiny.bvh: line 5121"), "{e}");
    assert!(e.contains("the rig is 1025 joints, over the limit of 1024 joints (joints per rig)"), "{e}");
}

#[test]
fn units_are_detected_from_the_rest_height() {
    assert_eq!(LengthUnit::detect(1.75), Some(LengthUnit::Metres));
    assert_eq!(LengthUnit::detect(173.0), Some(LengthUnit::Centimetres));
    assert_eq!(LengthUnit::detect(1650.0), Some(LengthUnit::Millimetres));
    assert_eq!(LengthUnit::detect(68.0), Some(LengthUnit::Inches));
    assert_eq!(LengthUnit::detect(25.4), Some(LengthUnit::CmuAsf));
    assert_eq!(LengthUnit::detect(0.0), None);
    assert_eq!(LengthUnit::detect(f64::NAN), None);
    assert!((LengthUnit::CmuAsf.metres() - 0.056444).abs() < 1e-6);
}
