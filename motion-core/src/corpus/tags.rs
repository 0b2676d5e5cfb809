//! What a window of motion does, measured from its own joints (not from its take's
//! description): speed, the direction of travel relative to the body's facing, turning, and
//! body states (crouched, sitting, on the floor, airborne, one foot off the ground for long,
//! hands above the head, hands together). The rules are plain thresholds on a floored motion
//! (floor y = 0, 20 fps, metres, +x the character's left), stated on each field.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::metrics::{heading_change_rad, longest_run, AIRBORNE_M};
use crate::representation::facing_direction;
use crate::skeleton::rest_pose;
use crate::skeleton::{Joint, Pose, FPS};

use super::prepare::STANCE_TOE_HEIGHT_M;

/// Horizontal direction of travel relative to the body's facing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TravelDirection {
    /// Along the facing direction.
    Forwards,
    /// Against it.
    Backwards,
    /// Towards the character's left (+x when facing +z).
    SidewaysLeft,
    /// Towards the character's right.
    SidewaysRight,
}

impl TravelDirection {
    /// The same direction seen in a left/right mirror.
    pub fn mirrored(self) -> Self {
        match self {
            TravelDirection::SidewaysLeft => TravelDirection::SidewaysRight,
            TravelDirection::SidewaysRight => TravelDirection::SidewaysLeft,
            other => other,
        }
    }
}

/// Measured tags of a window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MotionTags {
    /// Mean horizontal pelvis speed, m/s.
    pub speed_m_per_s: f64,
    /// Straight-line horizontal pelvis displacement from the first to the last frame, m.
    pub travel_m: f64,
    /// Where the body travels relative to its facing: the larger of the summed forward and
    /// sideways displacements over the frames moving faster than 0.3 m/s, when those frames
    /// cover at least 0.5 m; `None` for a body that stays in place.
    pub direction: Option<TravelDirection>,
    /// Signed turn of the facing direction, degrees, positive to the left.
    pub turn_deg: f64,
    /// Pelvis below 80 % and head below 90 % of their standing heights for at least half the
    /// frames, neither sitting nor on the floor.
    pub crouched: bool,
    /// Pelvis below 70 % of its standing height, within 15 cm of the knees' height, moving
    /// under 0.3 m/s, for at least 1 s.
    pub sitting: bool,
    /// Head lower than 0.6 m for at least a quarter of the frames (crawling, lying).
    pub on_floor: bool,
    /// Frames of flight: both toes more than 10 cm above the floor, in stretches of at most
    /// [`MAX_FLIGHT_FRAMES`] (longer ones stand on something the capture does not show: a
    /// stool, a step, uneven terrain). At least 2 make a jump or a hop.
    pub airborne_frames: usize,
    /// Longest stretch with one foot (toe and ankle) more than 10 cm above the floor while the
    /// other toe is within 5 cm of it, s.
    pub one_foot_up_s: f64,
    /// Frames with a wrist above the top of the head (the head joint plus [`HEAD_TOP_M`]; at
    /// least 10 count).
    pub hands_above_head_frames: usize,
    /// Frames with the wrists closer than 15 cm (at least 10 count).
    pub hands_together_frames: usize,
}

/// Height of the top of the head above the head joint, m (arms held out level are not above
/// the head).
pub const HEAD_TOP_M: f64 = 0.1;
/// Fewest frames of a hand state that count as doing it (0.5 s).
pub const HAND_STATE_FRAMES: usize = 10;
/// Longest flight of a jump or hop, frames (0.6 s: a 45 cm standing jump).
pub const MAX_FLIGHT_FRAMES: usize = 12;
/// Fewest airborne frames that make a jump or a hop.
pub const AIRBORNE_MIN_FRAMES: usize = 2;
/// Shortest one-foot stance that counts as a one-leg skill, s.
pub const ONE_FOOT_MIN_S: f64 = 1.5;
/// Smallest turn that counts as turning, degrees.
pub const TURN_MIN_DEG: f64 = 45.0;

impl MotionTags {
    /// Measures a floored window (≥ 2 frames).
    pub fn measure(poses: &[Pose]) -> Self {
        let n = poses.len().max(1);
        let pelvis = |t: usize| poses[t][Joint::Pelvis.index()];
        let horizontal = |v: DVec3| DVec3::new(v.x, 0.0, v.z);
        let path: f64 = poses.windows(2).map(|w| horizontal(w[1][0] - w[0][0]).length()).sum();
        let duration_s = (poses.len().saturating_sub(1)).max(1) as f64 / FPS;
        let travel_m = poses.last().map_or(0.0, |l| horizontal(l[0] - pelvis(0)).length());

        let standing = standing_pelvis_height();
        let head_standing = standing + (rest_pose()[Joint::Head.index()].y - rest_pose()[0].y);
        let low = |t: usize| pelvis(t).y < 0.8 * standing && poses[t][Joint::Head.index()].y < 0.9 * head_standing;
        let knees = |t: usize| 0.5 * (poses[t][Joint::LeftKnee.index()].y + poses[t][Joint::RightKnee.index()].y);
        let speed_at = |t: usize| {
            let (a, b) = (t.saturating_sub(2), (t + 2).min(poses.len() - 1));
            horizontal(pelvis(b) - pelvis(a)).length() * FPS / (b - a).max(1) as f64
        };
        let sit_frames = (0..poses.len())
            .map(|t| pelvis(t).y < 0.7 * standing && (pelvis(t).y - knees(t)).abs() < 0.15 && speed_at(t) < 0.3);
        let sitting = longest_run(sit_frames) as f64 / FPS >= 1.0;
        let on_floor = poses.iter().filter(|p| p[Joint::Head.index()].y < 0.6).count() * 4 >= n;
        let crouched = !sitting && !on_floor && (0..poses.len()).filter(|&t| low(t)).count() * 2 >= n;

        let up = |p: &Pose, toe: Joint, ankle: Joint| p[toe.index()].y > 0.10 && p[ankle.index()].y > 0.10;
        let down = |p: &Pose, toe: Joint| p[toe.index()].y < STANCE_TOE_HEIGHT_M + 0.05;
        let one_foot = poses.iter().map(|p| {
            (up(p, Joint::LeftFoot, Joint::LeftAnkle) && down(p, Joint::RightFoot))
                || (up(p, Joint::RightFoot, Joint::RightAnkle) && down(p, Joint::LeftFoot))
        });
        let count = |f: &dyn Fn(&Pose) -> bool| poses.iter().filter(|p| f(p)).count();
        let wrists = |p: &Pose| (p[Joint::LeftWrist.index()], p[Joint::RightWrist.index()]);
        Self {
            speed_m_per_s: path / duration_s,
            travel_m,
            direction: travel_direction(poses),
            turn_deg: heading_change_rad(poses).to_degrees(),
            crouched,
            sitting,
            on_floor,
            airborne_frames: flight_frames(poses),
            one_foot_up_s: longest_run(one_foot) as f64 / FPS,
            hands_above_head_frames: count(&|p| {
                let (l, r) = wrists(p);
                l.y.max(r.y) > p[Joint::Head.index()].y + HEAD_TOP_M
            }),
            hands_together_frames: count(&|p| {
                let (l, r) = wrists(p);
                (l - r).length() < 0.15
            }),
        }
    }

    /// Whether the window turns by at least [`TURN_MIN_DEG`]; `Some(true)` to the left.
    pub fn turn_left(&self) -> Option<bool> {
        (self.turn_deg.abs() >= TURN_MIN_DEG).then_some(self.turn_deg > 0.0)
    }

    /// Whether the body leaves the ground (a jump or a hop).
    pub fn airborne(&self) -> bool {
        self.airborne_frames >= AIRBORNE_MIN_FRAMES
    }

    /// Whether one foot stays off the ground for long (a one-leg stance or hop).
    pub fn one_foot(&self) -> bool {
        self.one_foot_up_s >= ONE_FOOT_MIN_S
    }

    /// Whether a wrist is above the head for long enough.
    pub fn hands_above_head(&self) -> bool {
        self.hands_above_head_frames >= HAND_STATE_FRAMES
    }

    /// Whether the wrists are together for long enough.
    pub fn hands_together(&self) -> bool {
        self.hands_together_frames >= HAND_STATE_FRAMES
    }

    /// The tags of the left/right mirrored window.
    pub fn mirrored(&self) -> Self {
        Self { direction: self.direction.map(TravelDirection::mirrored), turn_deg: -self.turn_deg, ..self.clone() }
    }
}

/// Pelvis height of the rest skeleton standing on the floor with its toes at
/// [`STANCE_TOE_HEIGHT_M`], m.
pub fn standing_pelvis_height() -> f64 {
    let rest = rest_pose();
    let toe = rest[Joint::LeftFoot.index()].y.min(rest[Joint::RightFoot.index()].y);
    rest[Joint::Pelvis.index()].y - toe + STANCE_TOE_HEIGHT_M
}

/// The direction of travel relative to facing (see [`MotionTags::direction`]).
fn travel_direction(poses: &[Pose]) -> Option<TravelDirection> {
    let (mut forward, mut left, mut moving) = (0.0, 0.0, 0.0);
    let mut facing = DVec3::Z;
    for w in poses.windows(2) {
        if let Some(f) = facing_direction(&w[0]) {
            facing = f;
        }
        let step = w[1][0] - w[0][0];
        let step = DVec3::new(step.x, 0.0, step.z);
        if step.length() * FPS < 0.3 {
            continue;
        }
        moving += step.length();
        forward += step.dot(facing);
        left += step.dot(DVec3::Y.cross(facing));
    }
    if moving < 0.5 {
        return None;
    }
    Some(if left.abs() > forward.abs() {
        if left > 0.0 {
            TravelDirection::SidewaysLeft
        } else {
            TravelDirection::SidewaysRight
        }
    } else if forward > 0.0 {
        TravelDirection::Forwards
    } else {
        TravelDirection::Backwards
    })
}

/// Frames in flights of at most [`MAX_FLIGHT_FRAMES`] with both toes above [`AIRBORNE_M`].
fn flight_frames(poses: &[Pose]) -> usize {
    let up: Vec<bool> =
        poses.iter().map(|p| p[Joint::LeftFoot.index()].y.min(p[Joint::RightFoot.index()].y) > AIRBORNE_M).collect();
    up.split(|u| !u).map(<[bool]>::len).filter(|&n| n <= MAX_FLIGHT_FRAMES).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::corpus::prepare::put_on_floor;
    use crate::motion::rotate_heading;
    use crate::motion::test_support::walking_poses;

    /// A floored walk of `frames` frames whose body is turned by `body_rad` against its path.
    fn walk_facing(frames: usize, body_rad: f64) -> Vec<Pose> {
        let walk = put_on_floor(&walking_poses(frames, 0.0));
        // Turn each pose's body about its own pelvis, keeping the pelvis path.
        walk.iter()
            .map(|p| {
                let c = DVec3::new(p[0].x, 0.0, p[0].z);
                let q = glam::DQuat::from_rotation_y(body_rad);
                p.map(|v| c + q * (v - c))
            })
            .collect()
    }

    #[test]
    fn a_walk_goes_forwards_and_a_body_turned_from_its_path_goes_sideways() {
        let tags = MotionTags::measure(&walk_facing(120, 0.0));
        assert_eq!(tags.direction, Some(TravelDirection::Forwards));
        assert!(tags.speed_m_per_s > 0.5 && tags.turn_left().is_none() && !tags.crouched && !tags.airborne());
        // The body faces 90° to the right of +z (towards -x) while walking along +z: its left is +z.
        let tags = MotionTags::measure(&walk_facing(120, -std::f64::consts::FRAC_PI_2));
        assert_eq!(tags.direction, Some(TravelDirection::SidewaysLeft));
        assert_eq!(tags.mirrored().direction, Some(TravelDirection::SidewaysRight));
        let tags = MotionTags::measure(&walk_facing(120, std::f64::consts::PI));
        assert_eq!(tags.direction, Some(TravelDirection::Backwards));
    }

    #[test]
    fn a_turning_walk_turns_its_way() {
        let left = MotionTags::measure(&put_on_floor(&walking_poses(120, 0.8)));
        assert_eq!(left.turn_left(), Some(true), "{}", left.turn_deg);
        let right = MotionTags::measure(&put_on_floor(&walking_poses(120, -0.8)));
        assert_eq!(right.turn_left(), Some(false));
        assert!(rotate_heading(&walking_poses(3, 0.0), 1.0).len() == 3);
    }

    #[test]
    fn a_lowered_walk_is_crouched_and_a_raised_one_airborne() {
        let walk = put_on_floor(&walking_poses(120, 0.0));
        let standing = standing_pelvis_height();
        // Crouch: everything above the knees lowered by 30 % of the standing pelvis height
        // (the legs fold; only heights matter to the tags).
        let crouch: Vec<Pose> = walk
            .iter()
            .map(|p| {
                let mut q = *p;
                for j in Joint::ALL {
                    if !matches!(j, Joint::LeftAnkle | Joint::RightAnkle | Joint::LeftFoot | Joint::RightFoot) {
                        q[j.index()].y -= 0.3 * standing;
                    }
                }
                q
            })
            .collect();
        let tags = MotionTags::measure(&crouch);
        assert!(tags.crouched && !tags.on_floor && !tags.sitting, "{tags:?}");
        assert!(!MotionTags::measure(&walk).crouched);
        // Jump: the whole body 30 cm up for frames 50..60.
        let jump: Vec<Pose> = walk
            .iter()
            .enumerate()
            .map(|(t, p)| if (50..60).contains(&t) { p.map(|v| v + DVec3::new(0.0, 0.3, 0.0)) } else { *p })
            .collect();
        let tags = MotionTags::measure(&jump);
        assert!(tags.airborne() && tags.airborne_frames == 10, "{tags:?}");
        // Standing on a step for 2 s is no flight.
        let step: Vec<Pose> = walk
            .iter()
            .enumerate()
            .map(|(t, p)| if (50..90).contains(&t) { p.map(|v| v + DVec3::new(0.0, 0.3, 0.0)) } else { *p })
            .collect();
        assert!(!MotionTags::measure(&step).airborne());
        assert!(!MotionTags::measure(&walk).airborne());
    }

    #[test]
    fn one_foot_up_for_two_seconds_and_hands_above_the_head_are_seen() {
        let rest = put_on_floor(&[rest_pose(); 50]);
        let mut stance = rest.clone();
        let mut hands_up = rest.clone();
        for p in stance.iter_mut() {
            for j in [Joint::LeftAnkle, Joint::LeftFoot] {
                p[j.index()].y += 0.2;
            }
        }
        for p in hands_up.iter_mut() {
            for j in [Joint::LeftWrist, Joint::RightWrist] {
                p[j.index()].y = p[Joint::Head.index()].y + 0.2;
            }
        }
        let tags = MotionTags::measure(&stance);
        assert!(tags.one_foot() && (tags.one_foot_up_s - 2.5).abs() < 1e-9, "{tags:?}");
        assert!(!MotionTags::measure(&rest).one_foot());
        let tags = MotionTags::measure(&hands_up);
        assert!(tags.hands_above_head() && !tags.hands_together() && tags.direction.is_none());
    }
}
