//! A self-contained 3-D viewer page: one HTML file holding three.js, the motions, the scene and
//! the report, that opens offline from the file system (no network, no sibling files).
//!
//! The page (`VIEWER_JS` on `TEMPLATE`) draws each sample as capsules (joints as spheres,
//! bones as cylinders; left limbs blue, right red, as in the strips), the scene boxes, a ground
//! grid with metre labels, the pelvis and foot paths, playback controls and the per-constraint
//! report, and each sample on the user's rig from its GLB (`--rig`: the skinned body played by
//! three.js's GLTFLoader and AnimationMixer at the page's time). three.js is the npm package
//! bundled into one script (`assets/viewer/README.md` says
//! how to rebuild it). Positions go in unchanged: the project's axes (m, y up, the character
//! starts facing +z, +x is its left) are three.js's own.

use std::path::Path;

use base64::Engine as _;
use serde::Serialize;

use super::error::{write_atomically, ExportError};
use super::scene::SceneBox;
use crate::program::Carry;
use crate::skeleton::{Joint, Pose, NUM_JOINTS};

/// The page: markup and style, with the three slots below.
const TEMPLATE: &str = include_str!("../../assets/viewer/template.html");
/// three.js and its OrbitControls as one minified script defining the global `THREE`.
const THREE_BUNDLE: &str = include_str!("../../assets/viewer/three.min.js");
/// The viewer itself (a classic script reading the data slot).
const VIEWER_JS: &str = include_str!("../../assets/viewer/viewer.js");

/// The slots of [`TEMPLATE`], in the order they appear in it.
const DATA_SLOT: &str = "/*@DATA@*/";
const THREE_SLOT: &str = "/*@THREE@*/";
const VIEWER_SLOT: &str = "/*@VIEWER@*/";

/// Joint positions are written rounded to 1/this m (0.1 mm: far below what a viewer shows, and
/// it keeps the page small).
const POSITION_STEPS_PER_M: f64 = 1e4;

/// One motion to show.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewerSample {
    /// Name in the sample switch and above the figure, e.g. `sample 0`.
    pub label: String,
    /// Joint positions per frame, m, in the project's axes; at least one frame.
    pub poses: Vec<Pose>,
}

/// Everything a viewer page shows.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewerInput {
    /// Heading and window title, e.g. the task's prompt.
    pub title: String,
    /// Frames per second of every sample (the project's motions: 20).
    pub fps: f64,
    /// The motions, drawn side by side in their own coordinates; samples may differ in length
    /// (a shorter one holds its last pose).
    pub samples: Vec<ViewerSample>,
    /// The scene's primitives as boxes ([`super::scene_boxes`]).
    pub scene: Vec<SceneBox>,
    /// Objects carried between the hands, drawn as balls of their diameter at the hands'
    /// midpoint in every sample.
    pub carried: Vec<Carry>,
    /// The run's `report.json` ([`crate::evaluation::TaskReport`]) for the constraint table;
    /// `None` for motions without a task.
    pub report: Option<serde_json::Value>,
    /// The samples on the user's rig (`--rig`): each one's GLB, played by the page.
    pub rigs: Vec<ViewerRig>,
}

/// One sample on the user's rig, as the page plays it.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewerRig {
    /// Drawn above the rig, e.g. `sample 0 on the rig mixamo`.
    pub label: String,
    /// The sample's GLB on the rig ([`super::gltf::glb_bytes`]): its skinned body and animation,
    /// at the motion's duration.
    pub glb: Vec<u8>,
}

/// What the page's data slot holds (documented at the top of `viewer.js`).
#[derive(Serialize)]
struct Payload<'a> {
    title: &'a str,
    fps: f64,
    joints: [&'static str; NUM_JOINTS],
    parents: [Option<usize>; NUM_JOINTS],
    samples: Vec<PayloadSample<'a>>,
    scene: &'a [SceneBox],
    carried: Vec<PayloadCarried>,
    report: Option<&'a serde_json::Value>,
    rigs: Vec<PayloadRig<'a>>,
}

#[derive(Serialize)]
struct PayloadRig<'a> {
    label: &'a str,
    /// The GLB, base64.
    glb_base64: String,
}

#[derive(Serialize)]
struct PayloadCarried {
    /// The two hands' joint indices.
    hands: [usize; 2],
    /// The ball's diameter, m.
    diameter_m: f64,
}

#[derive(Serialize)]
struct PayloadSample<'a> {
    label: &'a str,
    /// `[frame][joint][x, y, z]`, m.
    frames: Vec<[[f64; 3]; NUM_JOINTS]>,
}

fn validate(input: &ViewerInput) -> Result<(), ExportError> {
    if !(input.fps.is_finite() && input.fps > 0.0) {
        return Err(ExportError::Shape(format!("frame rate {} fps is not positive", input.fps)));
    }
    if input.samples.is_empty() {
        return Err(ExportError::Shape("no samples to show".into()));
    }
    for (s, sample) in input.samples.iter().enumerate() {
        if sample.poses.is_empty() {
            return Err(ExportError::Shape(format!("sample {s} (`{}`) has no frames", sample.label)));
        }
        for (frame, pose) in sample.poses.iter().enumerate() {
            if let Some((joint, p)) = Joint::ALL.iter().zip(pose).find(|(_, p)| !p.is_finite()) {
                return Err(ExportError::NonFinite { sample: s, frame, joint: joint.name(), value: p.to_array() });
            }
        }
    }
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if let Some(bad) =
        input.scene.iter().find(|b| !(finite(&b.centre_m) && finite(&b.half_extents_m) && finite(&b.rotation_xyzw)))
    {
        return Err(ExportError::Shape(format!("scene box `{}` is not finite", bad.name)));
    }
    Ok(())
}

fn rounded(pose: &Pose) -> [[f64; 3]; NUM_JOINTS] {
    pose.map(|p| p.to_array().map(|x| (x * POSITION_STEPS_PER_M).round() / POSITION_STEPS_PER_M))
}

/// The data slot's JSON; every `<` written as `\u003c`, so no string in it (a label holding
/// `</script>`) can close the script element that carries it.
fn payload_json(input: &ViewerInput) -> Result<String, ExportError> {
    let payload = Payload {
        title: &input.title,
        fps: input.fps,
        joints: Joint::ALL.map(Joint::name),
        parents: Joint::ALL.map(|j| j.parent().map(Joint::index)),
        samples: input
            .samples
            .iter()
            .map(|s| PayloadSample { label: &s.label, frames: s.poses.iter().map(rounded).collect() })
            .collect(),
        scene: &input.scene,
        carried: input
            .carried
            .iter()
            .map(|c| PayloadCarried { hands: c.hands.map(Joint::index), diameter_m: c.diameter_m })
            .collect(),
        report: input.report.as_ref(),
        rigs: input
            .rigs
            .iter()
            .map(|r| PayloadRig {
                label: &r.label,
                glb_base64: base64::engine::general_purpose::STANDARD.encode(&r.glb),
            })
            .collect(),
    };
    let json = serde_json::to_string(&payload).map_err(|e| ExportError::Shape(format!("viewer data: {e}")))?;
    Ok(json.replace('<', "\\u003c"))
}

/// `template` with each slot replaced by its text, the slots taken in order so that nothing
/// inserted is searched for a later slot.
fn fill(template: &str, slots: &[(&str, &str)]) -> Result<String, ExportError> {
    let mut out = String::with_capacity(template.len() + slots.iter().map(|(_, text)| text.len()).sum::<usize>());
    let mut rest = template;
    for (slot, text) in slots {
        let (before, after) =
            rest.split_once(slot).ok_or_else(|| ExportError::Shape(format!("viewer template has no slot {slot}")))?;
        out.push_str(before);
        out.push_str(text);
        rest = after;
    }
    out.push_str(rest);
    Ok(out)
}

/// The viewer page of `input`, as HTML.
///
/// Errors: no samples, a sample without frames, a frame rate that is not positive, or a
/// non-finite position ([`ExportError::NonFinite`] names the sample, frame and joint) or scene box.
pub fn viewer_html(input: &ViewerInput) -> Result<String, ExportError> {
    validate(input)?;
    let data = payload_json(input)?;
    fill(TEMPLATE, &[(DATA_SLOT, &data), (THREE_SLOT, THREE_BUNDLE), (VIEWER_SLOT, VIEWER_JS)])
}

/// Writes the viewer page of `input` to `path` (atomically).
pub fn write_viewer(path: &Path, input: &ViewerInput) -> Result<(), ExportError> {
    write_atomically(path, viewer_html(input)?.as_bytes())
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::export::SceneRole;

    fn pose(offset: f64) -> Pose {
        std::array::from_fn(|j| DVec3::new(offset, j as f64 * 0.08, 0.01 * j as f64))
    }

    fn input() -> ViewerInput {
        ViewerInput {
            title: "walk through the gap".into(),
            fps: 20.0,
            samples: vec![
                ViewerSample { label: "sample 0".into(), poses: vec![pose(0.0), pose(0.1)] },
                ViewerSample { label: "sample 1".into(), poses: vec![pose(1.0)] },
            ],
            scene: vec![SceneBox {
                name: "gap left wall".into(),
                role: SceneRole::Obstacle,
                centre_m: [0.35, 1.0, 2.0],
                half_extents_m: [0.05, 1.0, 1.5],
                rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            }],
            carried: vec![crate::program::Carry {
                hands: [Joint::LeftWrist, Joint::RightWrist],
                diameter_m: 0.3,
                clearance_m: 0.05,
                frames: Default::default(),
                reduce: Default::default(),
            }],
            report: Some(serde_json::json!({"constraints": [{"id": "c1", "pass": [true, false]}]})),
            rigs: Vec::new(),
        }
    }

    /// The JSON in the page's data slot.
    fn embedded(html: &str) -> serde_json::Value {
        let start = html.find(r#"id="viewer-data">"#).unwrap() + r#"id="viewer-data">"#.len();
        let end = start + html[start..].find("</script>").unwrap();
        serde_json::from_str(&html[start..end]).unwrap()
    }

    #[test]
    fn the_page_holds_the_data_the_bundle_and_the_viewer_and_nothing_external() {
        let html = viewer_html(&input()).unwrap();
        let data = embedded(&html);
        assert_eq!(data["samples"][1]["label"], "sample 1");
        assert_eq!(data["samples"][0]["frames"].as_array().unwrap().len(), 2);
        assert_eq!(data["samples"][0]["frames"][1][3], serde_json::json!([0.1, 0.24, 0.03]));
        assert_eq!(data["joints"][21], "right_wrist");
        assert_eq!(data["parents"][0], serde_json::Value::Null);
        assert_eq!(data["parents"][15], 12);
        assert_eq!(data["scene"][0]["role"], "obstacle");
        assert_eq!(data["carried"][0], serde_json::json!({"hands": [20, 21], "diameter_m": 0.3}));
        assert_eq!(data["report"]["constraints"][0]["id"], "c1");
        assert!(html.contains(THREE_BUNDLE) && html.contains(VIEWER_JS));
        assert!(!html.contains("/*@"), "a slot left unfilled");
        // Offline from file://: no scripts, styles or modules fetched from anywhere.
        for external in ["src=", "href=", "import(", "import {", "http://", "https://"] {
            assert!(!TEMPLATE.contains(external) && !VIEWER_JS.contains(external), "{external}");
        }
        assert!(!html.contains("<script src") && !html.contains("type=\"module\""));
    }

    #[test]
    fn a_missing_report_is_null() {
        let html = viewer_html(&ViewerInput { report: None, ..input() }).unwrap();
        assert_eq!(embedded(&html)["report"], serde_json::Value::Null);
    }

    #[test]
    fn a_label_cannot_close_the_data_script() {
        let mut bad = input();
        bad.samples[0].label = "</script><script>alert(1)</script>".into();
        bad.title = "<!-- a <b>title</b>".into();
        let html = viewer_html(&bad).unwrap();
        // The template's three scripts close once each; the label's tags are not in the page.
        assert_eq!(html.matches("</script>").count(), 3);
        assert!(!html.contains("<script>alert") && !html.contains("<!-- a"));
        assert_eq!(embedded(&html)["samples"][0]["label"], "</script><script>alert(1)</script>");
        assert_eq!(embedded(&html)["title"], "<!-- a <b>title</b>");
    }

    #[test]
    fn the_inlined_scripts_cannot_end_their_script_elements() {
        // Inside a <script>, `</script` ends it and `<!--` changes how the rest is parsed.
        for script in [THREE_BUNDLE, VIEWER_JS] {
            let lower = script.to_ascii_lowercase();
            assert!(!lower.contains("</script") && !lower.contains("<!--"));
        }
    }

    #[test]
    fn bad_inputs_are_refused_with_their_place() {
        let mut nan = input();
        nan.samples[1].poses[0][Joint::LeftWrist.index()].y = f64::NAN;
        let err = viewer_html(&nan).unwrap_err();
        assert!(matches!(err, ExportError::NonFinite { sample: 1, frame: 0, joint: "left_wrist", .. }), "{err}");
        type Spoil = fn(&mut ViewerInput);
        let cases: [(&str, Spoil); 5] = [
            ("no samples", |i| i.samples.clear()),
            ("has no frames", |i| i.samples[1].poses.clear()),
            ("not positive", |i| i.fps = 0.0),
            ("not positive", |i| i.fps = f64::INFINITY),
            ("gap left wall", |i| i.scene[0].half_extents_m[1] = f64::NAN),
        ];
        for (words, spoil) in cases {
            let mut bad = input();
            spoil(&mut bad);
            let err = viewer_html(&bad).unwrap_err();
            assert!(err.to_string().contains(words), "{words}: {err}");
        }
    }

    #[test]
    fn write_viewer_writes_the_page() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out").join("viewer.html");
        write_viewer(&path, &input()).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), viewer_html(&input()).unwrap());
    }
}
