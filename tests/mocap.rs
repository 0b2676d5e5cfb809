//! Real motion capture through the importers and the 263-d representation.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use e2e_tests::{fixtures, recover};
use motion_core::database::catalog::Catalog;
use motion_core::import::deepmimic::DeepMimicClip;
use motion_core::import::{resample, MocapClip};
use motion_core::motion::{bone_length_spread, rotate_heading};
use motion_core::representation::{extract_features, FOOT_CONTACT};
use motion_core::skeleton::{Joint, Pose, FPS};

fn deepmimic(name: &str) -> DeepMimicClip {
    DeepMimicClip::read(&fixtures().join("mocap/deepmimic").join(format!("{name}.txt"))).unwrap().0
}

fn max_error(a: &[Pose], b: &[Pose]) -> f64 {
    a.iter().zip(b).flat_map(|(p, q)| p.iter().zip(q).map(|(u, v)| (*u - *v).length())).fold(0.0, f64::max)
}

/// Every clip of the shipped prior's catalog and of the candidates imported for its next training.
#[test]
fn every_catalog_clip_round_trips_through_263_features_within_1mm() {
    let (mut sources, _) = Catalog::read(&fixtures().join("mocap/catalog.json")).unwrap().load().unwrap();
    assert!(sources.len() >= 20);
    let (candidates, _) = Catalog::read(&fixtures().join("mocap/catalog_candidates.json")).unwrap().load().unwrap();
    assert!(candidates.len() >= 4);
    sources.extend(candidates);
    for s in &sources {
        let poses = resample(s.clip.as_ref(), 1.0, s.clip.is_cyclic().then_some(6.0));
        let e = extract_features(&poses).unwrap();
        let back = recover(&e.features).unwrap();
        let err = max_error(&back, &e.canonical[..back.len()]);
        assert!(err <= 1e-3, "{}: max joint error {err} m", s.name);
        assert!(bone_length_spread(&poses) < 1e-3, "{}: bones stretch", s.name);
    }
}

#[test]
fn deepmimic_walk_has_human_height_speed_and_alternating_steps() {
    let walk = deepmimic("humanoid3d_walk");
    let poses = resample(&walk, 1.0, Some(8.0));
    let e = extract_features(&poses).unwrap();
    let c = &e.canonical;
    let head: Vec<f64> = c.iter().map(|p| p[Joint::Head.index()].y).collect();
    assert!(
        head.iter().all(|h| (1.45..=1.75).contains(h)),
        "head {:?}",
        head.iter().fold((9.0f64, 0.0f64), |a, h| (a.0.min(*h), a.1.max(*h)))
    );
    let seconds = (c.len() - 1) as f64 / FPS;
    let pelvis = |p: &Pose| glam::DVec2::new(p[0].x, p[0].z);
    let speed = (pelvis(&c[c.len() - 1]) - pelvis(&c[0])).length() / seconds;
    assert!((0.9..=1.1).contains(&speed), "forward speed {speed} m/s");
    // Alternating contacts: swing phases (at least 3 frames without toe contact) of the two
    // feet take turns, and each foot swings at least 5 times in 8 s.
    let swings = |k: usize| -> Vec<usize> {
        let on: Vec<bool> = e.features.iter().map(|f| f[FOOT_CONTACT.start + k] > 0.5).collect();
        (1..on.len().saturating_sub(3)).filter(|&t| on[t - 1] && on[t..t + 3].iter().all(|c| !c)).collect()
    };
    let (left, right) = (swings(1), swings(3));
    assert!(left.len() >= 5 && right.len() >= 5, "swings left {left:?}, right {right:?}");
    let mut order: Vec<(usize, char)> = left.iter().map(|t| (*t, 'L')).chain(right.iter().map(|t| (*t, 'R'))).collect();
    order.sort();
    assert!(order.windows(2).all(|w| w[0].1 != w[1].1), "feet do not alternate: {order:?}");
    assert!(bone_length_spread(&poses) < 1e-3);
}

#[test]
fn deepmimic_crawl_stays_low() {
    let crawl = deepmimic("humanoid3d_crawl");
    let e = extract_features(&resample(&crawl, 1.0, Some(6.0))).unwrap();
    let pelvis_max = e.canonical.iter().map(|p| p[0].y).fold(0.0, f64::max);
    assert!(pelvis_max < 0.45, "crawl pelvis up to {pelvis_max} m");
}

#[test]
fn features_do_not_depend_on_the_heading() {
    let walk = deepmimic("walker_turn_left1");
    let poses = resample(&walk, 1.0, Some(3.0));
    let a = extract_features(&poses).unwrap().features;
    let b = extract_features(&rotate_heading(&poses, 2.1)).unwrap().features;
    let diff = a.iter().zip(&b).flat_map(|(x, y)| x.iter().zip(y).map(|(u, v)| (u - v).abs())).fold(0.0f32, f32::max);
    assert!(diff < 1e-4, "features changed by {diff} under a heading rotation");
}

#[test]
fn looping_a_cycle_has_no_jumps() {
    // The seam blend must make the pose at the cycle end meet the next cycle's start.
    for name in ["humanoid3d_walk", "humanoid3d_run", "walker_turn_right0", "humanoid3d_spinkick"] {
        let clip = deepmimic(name);
        let d = clip.duration_s();
        let before = clip.pose_at(d - 1e-4);
        let after = clip.pose_at(d + 1e-4);
        let jump = before.iter().zip(&after).map(|(a, b)| (*a - *b).length()).fold(0.0, f64::max);
        assert!(jump < 0.01, "{name}: {jump} m jump at the loop seam");
    }
}
