//! Finding what in a take is not human motion, by measurement (no hand list of takes): glitch
//! frames (bones that stretch, joints that jump or spike for a frame), frozen stretches (the
//! same frame repeated, a tracking pause), calibration T-poses, and feet below the floor
//! (a take on stairs or a platform). A take is cut around what is dropped; stretches shorter
//! than a training window are dropped with it.

use serde::{Deserialize, Serialize};

use crate::skeleton::{bone_lengths, bones, Joint, Pose, NUM_JOINTS};

/// Why frames were dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DropReason {
    /// The take's positions are byte-identical to an earlier take's (the FBX library holds
    /// some takes twice under two ids).
    Duplicate,
    /// A bone deviates from the take's median length by more than [`ScreenConfig::bone_m`].
    BoneStretch,
    /// A joint's second difference exceeds [`ScreenConfig::spike_m_per_frame2`]: a jump or a
    /// one-frame spike no body makes.
    Spike,
    /// Every joint stands still to [`ScreenConfig::frozen_m`] for
    /// [`ScreenConfig::frozen_frames`] frames or more: the capture repeats a frame.
    Frozen,
    /// Arms spread level with the shoulders while the body stands still: a calibration pose.
    TPose,
    /// A joint more than [`ScreenConfig::under_floor_m`] below the floor under the stance feet
    /// (uneven ground: stairs, platforms, a jump down).
    UnderFloor,
    /// Standing still with the lower toe more than [`ScreenConfig::raised_m`] above the floor
    /// (on a step, a box, uneven terrain the capture does not show).
    RaisedStance,
    /// A stretch left between dropped frames that is shorter than
    /// [`ScreenConfig::min_segment_frames`].
    TooShort,
}

impl DropReason {
    /// Every reason, in report order.
    pub const ALL: [DropReason; 8] = [
        DropReason::Duplicate,
        DropReason::BoneStretch,
        DropReason::Spike,
        DropReason::Frozen,
        DropReason::TPose,
        DropReason::UnderFloor,
        DropReason::RaisedStance,
        DropReason::TooShort,
    ];

    /// What the reason means, for reports and the data card.
    pub fn describe(self) -> &'static str {
        match self {
            DropReason::Duplicate => "take identical to an earlier take",
            DropReason::BoneStretch => "a bone more than 3 cm off its median length",
            DropReason::Spike => "a joint jumping or spiking for a frame (> 1 m/frame²)",
            DropReason::Frozen => "the same frame repeated for 0.25 s or more",
            DropReason::TPose => "calibration T-pose",
            DropReason::UnderFloor => "a joint more than 3 cm under the floor (uneven ground)",
            DropReason::RaisedStance => "standing on something unseen (toes 8 cm up for 0.5 s)",
            DropReason::TooShort => "stretch shorter than 2 s left between drops",
        }
    }
}

/// Thresholds of the screen; defaults documented per field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenConfig {
    /// Largest deviation of a bone from its median length in the take, m (default 0.03).
    pub bone_m: f64,
    /// Largest second difference of a joint, m/frame² (default 1.0, i.e. 400 m/s² at 20 fps;
    /// the fastest real motion here, a backflip, bends at 0.74 and a run at 0.45).
    pub spike_m_per_frame2: f64,
    /// A joint that moves less than this in a frame stands still, m (default 0.0005).
    pub frozen_m: f64,
    /// Frames of a standing-still run of every joint that count as frozen (default 5, 0.25 s:
    /// a person standing still still sways by millimetres).
    pub frozen_frames: usize,
    /// Deepest a joint may go under the floor, m (default 0.03).
    pub under_floor_m: f64,
    /// Height of a standing toe above the floor that means the body stands on something, m
    /// (default 0.08).
    pub raised_m: f64,
    /// Frames dropped on each side of a dropped frame (default 2: 0.1 s).
    pub margin_frames: usize,
    /// Shortest stretch kept, frames (default 40: 2 s, the shortest training window).
    pub min_segment_frames: usize,
}

impl Default for ScreenConfig {
    fn default() -> Self {
        Self {
            bone_m: 0.03,
            spike_m_per_frame2: 1.0,
            frozen_m: 0.0005,
            frozen_frames: 5,
            under_floor_m: 0.03,
            raised_m: 0.08,
            margin_frames: 2,
            min_segment_frames: 40,
        }
    }
}

/// Per-frame verdicts of a take: `None` keeps the frame, `Some(reason)` drops it (the first
/// reason found wins).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameVerdicts(pub Vec<Option<DropReason>>);

impl FrameVerdicts {
    /// All frames kept.
    pub fn keep_all(frames: usize) -> Self {
        Self(vec![None; frames])
    }

    /// Marks `frames` with `reason` (unless already dropped), with `margin` frames either side.
    fn mark(&mut self, hits: impl IntoIterator<Item = usize>, reason: DropReason, margin: usize) {
        let n = self.0.len();
        for t in hits {
            for v in self.0.iter_mut().take((t + margin + 1).min(n)).skip(t.saturating_sub(margin)) {
                v.get_or_insert(reason);
            }
        }
    }

    /// The kept stretches (`start..end` frame ranges) at least `min_frames` long; shorter ones
    /// are marked [`DropReason::TooShort`].
    pub fn segments(&mut self, min_frames: usize) -> Vec<std::ops::Range<usize>> {
        let mut out = Vec::new();
        let mut t = 0;
        while t < self.0.len() {
            if self.0[t].is_some() {
                t += 1;
                continue;
            }
            let start = t;
            while t < self.0.len() && self.0[t].is_none() {
                t += 1;
            }
            if t - start >= min_frames {
                out.push(start..t);
            } else {
                self.0[start..t].iter_mut().for_each(|v| *v = Some(DropReason::TooShort));
            }
        }
        out
    }

    /// Frames dropped per reason.
    pub fn counts(&self) -> impl Iterator<Item = (DropReason, usize)> + '_ {
        DropReason::ALL.into_iter().map(|r| (r, self.0.iter().filter(|v| **v == Some(r)).count()))
    }
}

/// Screens a take as captured (before re-targeting): glitches, frozen stretches and T-poses.
pub fn screen_take(poses: &[Pose], config: &ScreenConfig) -> FrameVerdicts {
    let mut verdicts = FrameVerdicts::keep_all(poses.len());
    verdicts.mark(bone_stretch_frames(poses, config.bone_m), DropReason::BoneStretch, config.margin_frames);
    verdicts.mark(spike_frames(poses, config.spike_m_per_frame2), DropReason::Spike, config.margin_frames);
    verdicts.mark(frozen_frames(poses, config.frozen_m, config.frozen_frames), DropReason::Frozen, 0);
    verdicts.mark(t_pose_frames(poses), DropReason::TPose, config.margin_frames);
    verdicts
}

/// Marks the frames of a floored take (floor at y = 0) that put a joint more than
/// [`ScreenConfig::under_floor_m`] under the floor.
pub fn screen_floor(poses: &[Pose], verdicts: &mut FrameVerdicts, config: &ScreenConfig) {
    let under = poses.iter().enumerate().filter(|(_, p)| p.iter().any(|v| v.y < -config.under_floor_m)).map(|(t, _)| t);
    verdicts.mark(under.collect::<Vec<_>>(), DropReason::UnderFloor, config.margin_frames);
}

/// Marks the frames of a floored take in which the body stands on something: for 10 frames
/// (0.5 s) or more, both toes move horizontally slower than 0.3 m/s while the lower one is more
/// than [`ScreenConfig::raised_m`] above the floor and the pelvis is higher than a seated one
/// (70 % of its standing height).
pub fn screen_raised_stance(poses: &[Pose], verdicts: &mut FrameVerdicts, config: &ScreenConfig) {
    let toes = [Joint::LeftFoot.index(), Joint::RightFoot.index()];
    let standing = super::tags::standing_pelvis_height();
    let raised: Vec<bool> = (0..poses.len())
        .map(|t| {
            let (a, b) = (t.saturating_sub(1), (t + 1).min(poses.len().saturating_sub(1)));
            let still = toes.iter().all(|&j| {
                let d = poses[b][j] - poses[a][j];
                ((d.x * d.x + d.z * d.z).sqrt() * crate::skeleton::FPS / (b - a).max(1) as f64) < 0.3
            });
            let lower = poses[t][toes[0]].y.min(poses[t][toes[1]].y);
            still && lower > config.raised_m && poses[t][Joint::Pelvis.index()].y > 0.7 * standing
        })
        .collect();
    let mut hits = Vec::new();
    let mut t = 0;
    while t < raised.len() {
        let start = t;
        while t < raised.len() && raised[t] {
            t += 1;
        }
        if t - start >= 10 {
            hits.extend(start..t);
        }
        t += 1;
    }
    verdicts.mark(hits, DropReason::RaisedStance, config.margin_frames);
}

/// Frames at which some bone is more than `limit_m` off its median length over the take.
fn bone_stretch_frames(poses: &[Pose], limit_m: f64) -> Vec<usize> {
    let lengths: Vec<[f64; NUM_JOINTS]> = poses.iter().map(bone_lengths).collect();
    let medians: Vec<f64> = (0..NUM_JOINTS)
        .map(|j| {
            let mut column: Vec<f64> = lengths.iter().map(|l| l[j]).collect();
            column.sort_by(f64::total_cmp);
            column.get(column.len() / 2).copied().unwrap_or(0.0)
        })
        .collect();
    lengths
        .iter()
        .enumerate()
        .filter(|(_, l)| bones().any(|(_, child)| (l[child.index()] - medians[child.index()]).abs() > limit_m))
        .map(|(t, _)| t)
        .collect()
}

/// Interior frames at which some joint's second difference exceeds `limit` (m/frame²).
fn spike_frames(poses: &[Pose], limit: f64) -> Vec<usize> {
    poses
        .windows(3)
        .enumerate()
        .filter(|(_, w)| (0..NUM_JOINTS).any(|j| (w[2][j] - 2.0 * w[1][j] + w[0][j]).length() > limit))
        .map(|(t, _)| t + 1)
        .collect()
}

/// Frames inside runs of at least `min_run` frames in which no joint moves more than `still_m`
/// from the previous frame (both frames of each still pair count).
fn frozen_frames(poses: &[Pose], still_m: f64, min_run: usize) -> Vec<usize> {
    let still: Vec<bool> =
        poses.windows(2).map(|w| (0..NUM_JOINTS).all(|j| (w[1][j] - w[0][j]).length() <= still_m)).collect();
    let mut out = Vec::new();
    let mut t = 0;
    while t < still.len() {
        if !still[t] {
            t += 1;
            continue;
        }
        let start = t;
        while t < still.len() && still[t] {
            t += 1;
        }
        // Pairs start..t cover frames start..=t.
        if t - start + 1 >= min_run {
            out.extend(start..=t);
        }
    }
    out
}

/// Frames of a calibration T-pose: both wrists within 12 cm of their shoulder's height and
/// spread to at least 85 % of the arm span, the ankles within 45 cm of each other, and the
/// pelvis moving under 0.3 m/s.
fn t_pose_frames(poses: &[Pose]) -> Vec<usize> {
    let j = |p: &Pose, joint: Joint| p[joint.index()];
    poses
        .iter()
        .enumerate()
        .filter(|(t, p)| {
            let arm = |s, e, w| (j(p, e) - j(p, s)).length() + (j(p, w) - j(p, e)).length();
            let span = arm(Joint::LeftShoulder, Joint::LeftElbow, Joint::LeftWrist)
                + arm(Joint::RightShoulder, Joint::RightElbow, Joint::RightWrist)
                + (j(p, Joint::LeftShoulder) - j(p, Joint::RightShoulder)).length();
            let level = (j(p, Joint::LeftWrist).y - j(p, Joint::LeftShoulder).y).abs() < 0.12
                && (j(p, Joint::RightWrist).y - j(p, Joint::RightShoulder).y).abs() < 0.12;
            let spread = (j(p, Joint::LeftWrist) - j(p, Joint::RightWrist)).length() > 0.85 * span;
            let feet = (j(p, Joint::LeftAnkle) - j(p, Joint::RightAnkle)).length() < 0.45;
            let prev = poses.get(t.saturating_sub(1)).unwrap_or(p);
            let still = (j(p, Joint::Pelvis) - j(prev, Joint::Pelvis)).length() * crate::skeleton::FPS < 0.3;
            level && spread && feet && still
        })
        .map(|(t, _)| t)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::test_support::walking_poses;
    use glam::DVec3;

    #[test]
    fn a_clean_walk_keeps_every_frame() {
        let walk = walking_poses(120, 0.0);
        let mut v = screen_take(&walk, &ScreenConfig::default());
        assert_eq!(v.segments(40), vec![0..120]);
    }

    #[test]
    fn a_one_frame_jump_and_a_stretched_bone_cut_the_take_with_margins() {
        let mut walk = walking_poses(200, 0.0);
        walk[50][Joint::LeftWrist.index()] += DVec3::new(0.0, 0.6, 0.0);
        let v = screen_take(&walk, &ScreenConfig::default());
        assert_eq!(v.0[50], Some(DropReason::BoneStretch));
        assert_eq!(v.0[48], Some(DropReason::BoneStretch));
        assert_eq!(v.0[47], None);
        // Far from the stretch, an off-axis jump of the whole body by 1.2 m is a spike.
        for p in walk.iter_mut().skip(150) {
            for q in p.iter_mut() {
                *q += DVec3::new(1.2, 0.0, 0.0);
            }
        }
        let mut v = screen_take(&walk, &ScreenConfig::default());
        assert!(v.0[149..=150].iter().all(|r| *r == Some(DropReason::Spike)), "{:?}", &v.0[145..155]);
        let segments = v.segments(40);
        assert_eq!(segments, vec![0..48, 53..147, 153..200]);
    }

    #[test]
    fn repeated_frames_are_frozen_and_a_short_stretch_between_drops_is_too_short() {
        let mut walk = walking_poses(200, 0.0);
        for t in 100..110 {
            walk[t] = walk[99];
        }
        let v = screen_take(&walk, &ScreenConfig::default());
        assert!(v.0[99..110].iter().all(|r| *r == Some(DropReason::Frozen)));
        assert_eq!(v.0[98], None);
        for t in 130..140 {
            walk[t] = walk[129];
        }
        let mut v = screen_take(&walk, &ScreenConfig::default());
        let segments = v.segments(40);
        // The catch-up after a freeze may spike too; what lies between the freezes is too short.
        assert_eq!(segments.first(), Some(&(0..99)));
        assert!(segments.len() == 2 && segments[1].start >= 140 && segments[1].end == 200, "{segments:?}");
        assert!(v.0[110..129].iter().all(|r| r.is_some()));
        assert!(v.0[110..129].contains(&Some(DropReason::TooShort)));
    }

    #[test]
    fn a_t_pose_is_dropped_but_arms_raised_forward_are_not() {
        let rest = crate::skeleton::rest_pose();
        let mut t_pose = rest;
        for (s, e, w, side) in [
            (Joint::LeftShoulder, Joint::LeftElbow, Joint::LeftWrist, 1.0),
            (Joint::RightShoulder, Joint::RightElbow, Joint::RightWrist, -1.0),
        ] {
            let (l1, l2) = ((rest[e.index()] - rest[s.index()]).length(), (rest[w.index()] - rest[e.index()]).length());
            t_pose[e.index()] = rest[s.index()] + DVec3::new(side * l1, 0.0, 0.0);
            t_pose[w.index()] = t_pose[e.index()] + DVec3::new(side * l2, 0.0, 0.0);
        }
        let mut arms_forward = t_pose;
        for w in [Joint::LeftElbow, Joint::LeftWrist, Joint::RightElbow, Joint::RightWrist] {
            let s = if matches!(w, Joint::LeftElbow | Joint::LeftWrist) {
                Joint::LeftShoulder
            } else {
                Joint::RightShoulder
            };
            let d = t_pose[w.index()] - t_pose[s.index()];
            arms_forward[w.index()] = t_pose[s.index()] + DVec3::new(0.0, 0.0, d.length());
        }
        assert_eq!(t_pose_frames(&[t_pose; 4]), vec![0, 1, 2, 3]);
        assert!(t_pose_frames(&[arms_forward; 4]).is_empty());
        assert!(t_pose_frames(&[rest; 4]).is_empty());
    }

    #[test]
    fn joints_under_the_floor_are_dropped() {
        let mut walk = walking_poses(100, 0.0);
        walk[60][Joint::LeftFoot.index()].y = -0.05;
        let mut v = FrameVerdicts::keep_all(walk.len());
        screen_floor(&walk, &mut v, &ScreenConfig::default());
        assert_eq!(v.0[60], Some(DropReason::UnderFloor));
        assert_eq!(v.counts().find(|(r, _)| *r == DropReason::UnderFloor).map(|c| c.1), Some(5));
    }

    #[test]
    fn standing_on_a_step_is_dropped_but_a_jump_is_not() {
        let rest = crate::skeleton::rest_pose();
        let floor = rest.iter().map(|v| v.y).fold(f64::INFINITY, f64::min);
        let standing: Vec<Pose> = (0..60).map(|_| rest.map(|v| v - DVec3::new(0.0, floor, 0.0))).collect();
        let mut on_step = standing.clone();
        on_step[20..40].iter_mut().for_each(|p| p.iter_mut().for_each(|v| v.y += 0.2));
        let mut v = FrameVerdicts::keep_all(60);
        screen_raised_stance(&on_step, &mut v, &ScreenConfig::default());
        assert!(v.0[20..40].iter().all(|r| *r == Some(DropReason::RaisedStance)));
        assert_eq!(v.0[17], None);
        let mut jump = standing;
        jump[20..26].iter_mut().for_each(|p| p.iter_mut().for_each(|v| v.y += 0.2));
        let mut v = FrameVerdicts::keep_all(60);
        screen_raised_stance(&jump, &mut v, &ScreenConfig::default());
        assert!(v.0.iter().all(Option::is_none));
    }
}
