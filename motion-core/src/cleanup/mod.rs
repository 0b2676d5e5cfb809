//! Contact-aware clean-up of a finished motion: feet that stay planted.
//!
//! [`fn@foot_lock`] is the foot locking animation tools apply to captured or generated motion
//! (Kovar, Schreiner & Gleicher 2002, "Footskate cleanup for motion capture editing"), on joint
//! positions (m, y up, 20 fps, floor y = 0):
//! 1. **Floor** ([`contact::floor_height`]): a body hovering above the floor by more than
//!    [`FootLockConfig::float_tolerance_m`] is lowered as a whole (every joint, the pelvis
//!    included) onto it; frames in which a joint sinks below the floor are raised as a whole
//!    by at least that depth, the raise spread over [`SINK_RAISE_FRAMES`] frames on either side
//!    ([`contact::sinking_lift`]). Generated motions float or sink a few centimetres; these
//!    vertical offsets are the only change to the pelvis and the upper body.
//! 2. **Contacts** ([`contact::detect`]): each of the four [`CONTACT_JOINTS`] (ankles, toes) is
//!    in contact while it is low above the floor and slow, with hysteresis; contacts shorter
//!    than [`FootLockConfig::min_contact_frames`] are dropped. Callers holding contact labels
//!    (the 263-d features' four channels) can pass them instead.
//! 3. **Locks** ([`foot_lock::Lock`]): per contact, the joint is held at its mean horizontal
//!    position (over the contact's steadiest stretch when it slides farther than
//!    [`FootLockConfig::max_lock_offset_m`] from that mean, [`foot_lock::steadiest`]) and
//!    lifted so that its median height comes within [`FootLockConfig::height_tolerance_m`] of its standing height (it keeps its own small
//!    vertical motion, such as a heel rising before the foot leaves); it eases back to its own
//!    motion over [`FootLockConfig::blend_frames`] frames on either side, more for a large
//!    offset ([`FootLockConfig::blend_speed_m_per_s`]), so nothing pops.
//! 4. **Leg IK** ([`solve_leg`] in `motion::leg_ik`): hip fixed, knee in its original bend plane (summed
//!    over ±[`KNEE_BEND_FRAMES`](crate::motion::leg_ik::KNEE_BEND_FRAMES) frames, [`knee_poles`]), thigh,
//!    shin and foot lengths kept exactly; a free ankle follows its toe's correction (and a free
//!    toe its ankle's), so the foot turns about the planted joint. A target out of the leg's
//!    reach gives the closest point the leg reaches with the knee a little bent (soft reach,
//!    [`FootLockConfig::soft_reach_m`]) and is counted. The IK never takes a knee, ankle or toe
//!    below the floor, nor deeper than it was, with planting on or off
//!    ([`FootLockConfig::keep_above_floor`]; without it, GEO-2's walks beside a raised beam, with
//!    planting off, get a toe pushed 7 cm under the floor): where the full correction would, the
//!    leg takes the largest fraction of it that does not (`floor_safe_fraction`), and
//!    neighbouring frames ease into that fraction at most [`FLOOR_FRACTION_STEP`] per frame (each
//!    eased fraction is checked again). (Without these checks a lock lowering a stance ankle to
//!    its standing height pushes its toe, or a crawl's knee, up to 7 cm through the floor; both
//!    figures are in `fixtures/results/README.md`.)
//! 5. **Judged** (`locks_help`): the locks and IK are kept only where they do not raise the
//!    foot skate of the motion on the floor nor jerk it beyond capture's peak acceleration;
//!    otherwise the motion is only set on the floor (a crawl's feet drag along it by design).
//!
//! Only the knees, ankles and toes move (and the whole body by the floor offset), so a
//! constraint on any other joint keeps its error exactly unless the body is lowered. A
//! constraint on the legs or the centre of mass may change: on the shipped walking clips and
//! tasks no task constraint's error `E` rises above
//! `E·(1 + CONSTRAINT_TOLERANCE_RELATIVE) + CONSTRAINT_TOLERANCE_ABSOLUTE` (tested in
//! `tests.rs`); `stay_near_initial` regularisers, which measure how far joints moved, are
//! excepted.

pub mod contact;
pub mod foot_lock;

#[cfg(test)]
mod tests;

use std::ops::Range;

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::metrics::{foot_skate_ratio, max_acceleration, CAPTURE_MAX_ACCELERATION, LOOK_SLACK};
use crate::motion::leg_ik::{knee_poles, solve_leg, Leg, LegSolution};
use crate::skeleton::{bone_lengths, Joint, Pose, CONTACT_JOINTS, FPS, NUM_JOINTS};
use crate::MotionError;
use contact::{detect, floor_height, runs, sinking_lift, speeds, Hysteresis};
use foot_lock::{corrections, steadiest, Correction, Easing, Lock};

/// The clean-up raises no task constraint's error `E` by more than this fraction of `E` ...
pub const CONSTRAINT_TOLERANCE_RELATIVE: f64 = 0.05;
/// ... plus this, in the constraint's own unit (m² for squared position errors: a 1 cm miss).
pub const CONSTRAINT_TOLERANCE_ABSOLUTE: f64 = 1e-4;

/// Frames on either side over which a sinking frame's raise is spread (0.2 s at 20 fps).
pub const SINK_RAISE_FRAMES: usize = 4;

/// Largest change per frame of the fraction of a leg's correction the floor lets through: a
/// leg whose correction is held back for the floor eases into and out of it over 4 frames.
pub const FLOOR_FRACTION_STEP: f64 = 0.25;

/// How far below the floor, or below where it was, the IK may leave a joint, m (round-off).
const FLOOR_SLACK_M: f64 = 1e-3;

/// Settings of [`fn@foot_lock`]. Heights and speeds were measured on the shipped walking clips
/// (`fixtures/mocap`, the DeepMimic walks): standing ankles at 5.9–7.2 cm (median per clip),
/// standing toes at 1.5–2.4 cm; stance joints move at about 0.1 m/s, swinging feet at 1–4 m/s.
/// Fields missing from a deserialised config take their defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FootLockConfig {
    /// Run the clean-up (default true); `false` returns the motion unchanged.
    pub enabled: bool,
    /// Height of an ankle joint when its foot stands on the floor, m (default 0.065, the
    /// walks' median; the rest pose puts the ankle 4.7 cm above the toe, feet flat).
    pub ankle_height_m: f64,
    /// Height of a toe-ball joint (`*_foot`) when it rests on the floor, m (default 0.02).
    pub toe_height_m: f64,
    /// A joint enters contact below this height above its standing height, m (default 0.02),
    /// heights measured from the motion's floor (its [`contact::floor_height`] where it floats
    /// less than `float_tolerance_m`, else y = 0) ...
    pub enter_height_m: f64,
    /// ... while slower than this, m/s (default 1.0: generated feet slide at up to about
    /// 1 m/s in stance; the skate metric counts 0.5 m/s).
    pub enter_speed_m_per_s: f64,
    /// It stays in contact below this height above its standing height, m (default 0.03) ...
    pub leave_height_m: f64,
    /// ... while slower than this, m/s (default 1.5).
    pub leave_speed_m_per_s: f64,
    /// A contact whose median height is within this of the joint's standing height keeps its
    /// height; one farther away is brought this close, m (default 0.01: the walks' stance
    /// heights vary by about ±1 cm between clips).
    pub height_tolerance_m: f64,
    /// Contacts shorter than this are dropped, frames (default 3).
    pub min_contact_frames: usize,
    /// A locked joint is held at most this far (horizontally) from where the motion puts it, m
    /// (default 0.15, under a foot's length): a contact over which it slides farther is cut to
    /// its steadiest stretch ([`foot_lock::steadiest`]) and dropped if that is shorter than
    /// `min_contact_frames`. Holding a long slide at its mean drags the leg by half the slide.
    pub max_lock_offset_m: f64,
    /// Frames over which a lock eases in before and out after its contact, at least (default 3)
    /// ...
    pub blend_frames: usize,
    /// ... and more where needed for the easing to move a joint by at most this speed, m/s
    /// (default 0.5, the skate metric's threshold): a foot held far from where it slid to is
    /// let go of gradually.
    pub blend_speed_m_per_s: f64,
    /// Width of the soft zone below a leg's full reach, m (default 0.02; [`soft_reach`](crate::motion::leg_ik::soft_reach)):
    /// a held foot the hip pulls out of reach then follows it smoothly instead of snapping
    /// the knee straight. With 2 cm, generated walks keep their knees as bent as the shipped
    /// walks do (5 % of leg-frames under 9.1° against the clips' 5.7–9.8°, none under 4.5°
    /// against their 1.9–4.2°); 1 cm straightens them beyond the data (4.0°, 1.0°), and a held
    /// stance foot is then let go with a jolt as its leg reaches full length (0.078 → 0.072
    /// m/frame² on Task-3's RG-DNO samples, the clean-up's added acceleration 11 % lower;
    /// `fixtures/results/README.md`).
    pub soft_reach_m: f64,
    /// Plant contacts on the floor y = 0: lower a floating body, raise sinking frames, and bring
    /// locked joints within `height_tolerance_m` of their standing heights (default true).
    /// Switch off for motions on raised supports (a balance beam): locks then hold only
    /// horizontally, and the body keeps its height.
    pub plant_on_floor: bool,
    /// Keep the leg IK out of the ground: no knee, ankle or toe lower than the floor y = 0 or
    /// than it was (default true), with planting on or off. Switch off only where the ground
    /// itself lies below y = 0 (a pit).
    pub keep_above_floor: bool,
    /// A body floating less than this above the floor is not lowered, m (default 0.02): its
    /// stance feet come within `height_tolerance_m` of the floor through the leg IK.
    pub float_tolerance_m: f64,
    /// Keep the locks only where they help (`locks_help`; default true): otherwise the motion
    /// is only set on the floor. Off, the locks stay whatever they do (the papers' schedule,
    /// whose motions stay those of the builds before this judgement).
    pub judge_locks: bool,
}

impl Default for FootLockConfig {
    fn default() -> Self {
        FootLockConfig {
            enabled: true,
            ankle_height_m: 0.065,
            toe_height_m: 0.02,
            enter_height_m: 0.02,
            enter_speed_m_per_s: 1.0,
            leave_height_m: 0.03,
            leave_speed_m_per_s: 1.5,
            height_tolerance_m: 0.01,
            min_contact_frames: 3,
            max_lock_offset_m: 0.15,
            blend_frames: 3,
            blend_speed_m_per_s: 0.5,
            soft_reach_m: 0.02,
            plant_on_floor: true,
            keep_above_floor: true,
            float_tolerance_m: 0.02,
            judge_locks: true,
        }
    }
}

impl FootLockConfig {
    /// Standing heights of the four [`CONTACT_JOINTS`], m.
    fn standing_m(&self) -> [f64; 4] {
        [self.ankle_height_m, self.toe_height_m, self.ankle_height_m, self.toe_height_m]
    }

    fn easing(&self) -> Easing {
        Easing { min_frames: self.blend_frames, max_step_m: self.blend_speed_m_per_s / FPS }
    }

    fn hysteresis(&self) -> Hysteresis {
        Hysteresis {
            enter_height_m: self.enter_height_m,
            enter_speed_m_per_s: self.enter_speed_m_per_s,
            leave_height_m: self.leave_height_m,
            leave_speed_m_per_s: self.leave_speed_m_per_s,
        }
    }
}

/// Contacts of one foot joint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointContacts {
    /// The joint (one of [`CONTACT_JOINTS`]).
    pub joint: Joint,
    /// The contact segments locked: half-open frame ranges, in order.
    pub segments: Vec<Range<usize>>,
    /// Frames inside those segments.
    pub locked_frames: usize,
}

/// What [`fn@foot_lock`] did, with the figures before and after it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FootLockReport {
    /// Whether the clean-up ran.
    pub enabled: bool,
    /// Height of the floor under the input motion ([`contact::floor_height`]), m.
    pub floor_m: f64,
    /// How far the whole body was lowered, m (0 or `floor_m`).
    pub lowered_m: f64,
    /// Largest raise of a sinking frame, m (0 when no joint sank below the floor).
    #[serde(default)]
    pub raised_m: f64,
    /// Contacts per joint, in [`CONTACT_JOINTS`] order.
    pub contacts: [JointContacts; 4],
    /// Contacts cut to their steadiest stretch (or dropped) because the joint slid farther
    /// than [`FootLockConfig::max_lock_offset_m`] from the hold.
    pub shortened: usize,
    /// Leg solves whose ankle target was out of the leg's reach (one per leg and frame).
    pub unreachable: usize,
    /// Leg solves that took only part of their correction so as not to push a joint through
    /// the floor (one per leg and frame).
    #[serde(default)]
    pub held_above_floor: usize,
    /// Largest joint displacement, m.
    pub max_displacement_m: f64,
    /// Mean displacement over every joint of every frame, m.
    pub mean_displacement_m: f64,
    /// [`foot_skate_ratio`] of the input.
    pub skate_before: f64,
    /// [`foot_skate_ratio`] of the output.
    pub skate_after: f64,
    /// Largest change of any bone's length in any frame, m (round-off only).
    pub max_bone_length_change_m: f64,
    /// The program's constraints that the motion met before the clean-up and that the cleaned
    /// motion would fail. When any is named, the clean-up is undone for this sample (its motion
    /// is the one before it; the figures above are of the undone clean-up).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub undone_for: Vec<String>,
    /// Whether the locks were given up because they would raise the foot skate or jerk the
    /// motion (`locks_help`): the motion is then only set on the floor (the contacts and
    /// counts above are of the locks given up).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub locks_given_up: bool,
}

/// A cleaned motion and its report.
#[derive(Debug, Clone, PartialEq)]
pub struct FootLocked {
    /// The motion, `[frames]` of poses (m, y up).
    pub poses: Vec<Pose>,
    /// What was done.
    pub report: FootLockReport,
}

/// Why [`fn@foot_lock`] refused a motion.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FootLockError {
    /// The contact labels do not cover the motion frame for frame.
    #[error("contact labels cover {labels} frames; the motion has {frames}")]
    ContactFrames {
        /// Frames of labels given.
        labels: usize,
        /// Frames of the motion.
        frames: usize,
    },
    /// The motion itself is unusable.
    #[error(transparent)]
    Motion(#[from] MotionError),
}

/// The two legs: hip, knee, then the indices of the ankle and toe in [`CONTACT_JOINTS`].
const LEGS: [(Joint, Joint, usize, usize); 2] =
    [(Joint::LeftHip, Joint::LeftKnee, 0, 1), (Joint::RightHip, Joint::RightKnee, 2, 3)];

/// Locks the feet of `poses` (`[frames]`, m, y up, 20 fps) during their contacts (see the
/// module docs). `contacts`, when given, labels each frame's contacts in [`CONTACT_JOINTS`]
/// order `[left_ankle, left_foot, right_ankle, right_foot]` (the 263-d features' channels) and
/// replaces detection.
pub fn foot_lock(
    poses: &[Pose],
    contacts: Option<&[[bool; 4]]>,
    config: &FootLockConfig,
) -> Result<FootLocked, FootLockError> {
    if let Some(labels) = contacts.filter(|c| c.len() != poses.len()) {
        return Err(FootLockError::ContactFrames { labels: labels.len(), frames: poses.len() });
    }
    for (frame, pose) in poses.iter().enumerate() {
        if let Some(joint) = Joint::ALL.into_iter().find(|j| !pose[j.index()].is_finite()) {
            return Err(MotionError::NonFinite { frame, joint }.into());
        }
    }
    let standing = config.standing_m();
    let floor_m = floor_height(poses, &standing);
    if !config.enabled {
        let report = report(poses, poses, (floor_m, 0.0, 0.0), None, Counts::default());
        return Ok(FootLocked { poses: poses.to_vec(), report });
    }

    // 1. Floor: lower a floating body as a whole, raise the frames that sink.
    let lowered_m = if config.plant_on_floor && floor_m > config.float_tolerance_m { floor_m } else { 0.0 };
    let mut out: Vec<Pose> = poses.iter().map(|p| p.map(|v| v - DVec3::Y * lowered_m)).collect();
    let raise = if config.plant_on_floor { sinking_lift(&out, SINK_RAISE_FRAMES) } else { vec![0.0; out.len()] };
    for (pose, r) in out.iter_mut().zip(&raise) {
        *pose = pose.map(|v| v + DVec3::Y * *r);
    }
    // The motion on the floor, kept only when the locks are to be judged against it.
    let floored = config.judge_locks.then(|| out.clone());

    // 2–3. Contacts and the correction of each foot joint.
    let mut locked: [Vec<Range<usize>>; 4] = Default::default();
    let mut correction: Vec<Vec<Correction>> = Vec::with_capacity(4);
    let mut shortened = 0;
    let min_frames = config.min_contact_frames.max(1);
    for (k, joint) in CONTACT_JOINTS.iter().enumerate() {
        let track: Vec<DVec3> = out.iter().map(|p| p[joint.index()]).collect();
        let segments = match contacts {
            Some(labels) => runs(labels.iter().map(|c| c[k])),
            None => {
                // Measured from y = 0 under a sinking motion: its sunk feet count as low. The
                // raise of sinking frames is left out, so it does not end a contact.
                let floor = (floor_m - lowered_m).max(0.0);
                let clearance: Vec<f64> =
                    track.iter().zip(&raise).map(|(v, r)| v.y - r - floor - standing[k]).collect();
                detect(&clearance, &speeds(&track), &config.hysteresis())
            }
        };
        let locks: Vec<Lock> = segments
            .into_iter()
            .filter(|s| s.len() >= min_frames)
            .map(|s| {
                let held = steadiest(&track, s.clone(), config.max_lock_offset_m);
                shortened += usize::from(held != s);
                held
            })
            .filter(|s| s.len() >= min_frames)
            .map(|s| Lock::new(&track, s, config.plant_on_floor.then_some(standing[k]), config.height_tolerance_m))
            .collect();
        locked[k] = locks.iter().map(|l| l.frames.clone()).collect();
        correction.push(corrections(&track, &locks, &config.easing()));
    }

    // 4. Leg IK towards the corrected ankle and toe, kept above the floor.
    let (mut unreachable, mut held_above_floor) = (0, 0);
    for (hip, knee, a, b) in LEGS {
        let (ankle, toe) = (CONTACT_JOINTS[a].index(), CONTACT_JOINTS[b].index());
        let moved = |t: usize| correction[a][t].weight > 0.0 || correction[b][t].weight > 0.0;
        let legs: Vec<Leg> = out
            .iter()
            .map(|p| Leg { hip: p[hip.index()], knee: p[knee.index()], ankle: p[ankle], toe: p[toe] })
            .collect();
        let forwards: Vec<DVec3> =
            out.iter().map(|p| (p[Joint::LeftHip.index()] - p[Joint::RightHip.index()]).cross(DVec3::Y)).collect();
        let poles = knee_poles(&legs, &forwards);
        // The leg of frame t solved towards `fraction` of its correction.
        let solve = |t: usize, fraction: f64| {
            let leg = legs[t];
            let (ankle_c, toe_c) = (correction[a][t], correction[b][t]);
            // A free joint follows its partner's correction: the foot rolls about the held one.
            let ankle_offset = ankle_c.offset + (1.0 - ankle_c.weight) * toe_c.offset;
            let toe_offset = toe_c.offset + (1.0 - toe_c.weight) * ankle_c.offset;
            let target = |joint: DVec3, offset: DVec3| joint + fraction * offset;
            let solved = solve_leg(
                &leg,
                target(leg.ankle, ankle_offset),
                target(leg.toe, toe_offset),
                poles[t],
                config.soft_reach_m,
            );
            (leg, solved)
        };
        let guarded = |t: usize| moved(t) && config.keep_above_floor;
        let fractions: Vec<f64> =
            (0..out.len()).map(|t| if guarded(t) { floor_safe_fraction(|f| solve(t, f), 1.0) } else { 1.0 }).collect();
        // Easing lowers fractions, and a lower one need not keep the leg above the floor
        // either (the knee swings as the ankle moves): each eased one is checked again.
        let fractions: Vec<f64> = ease_down(&fractions, FLOOR_FRACTION_STEP)
            .into_iter()
            .enumerate()
            .map(|(t, f)| if guarded(t) { floor_safe_fraction(|g| solve(t, g), f) } else { f })
            .collect();
        let solutions: Vec<Option<(f64, LegSolution)>> =
            fractions.iter().enumerate().map(|(t, &f)| moved(t).then(|| (f, solve(t, f).1))).collect();
        for (pose, (fraction, solved)) in out.iter_mut().zip(solutions).filter_map(|(p, s)| Some((p, s?))) {
            unreachable += usize::from(!solved.reached);
            held_above_floor += usize::from(fraction < 1.0);
            pose[knee.index()] = solved.leg.knee;
            pose[ankle] = solved.leg.ankle;
            pose[toe] = solved.leg.toe;
        }
    }
    let raised_m = raise.iter().copied().fold(0.0, f64::max);
    let counts = Counts { shortened, unreachable, held_above_floor };
    let given_up = floored.filter(|floored| !locks_help(floored, &out));
    let locks_given_up = given_up.is_some();
    if let Some(floored) = given_up {
        out = floored;
    }
    let mut report = report(poses, &out, (floor_m, lowered_m, raised_m), Some(locked), counts);
    report.locks_given_up = locks_given_up;
    Ok(FootLocked { poses: out, report })
}

/// Whether the locks and the leg IK (giving `locked`) improve on the motion on the floor they
/// start from (`floored`): no more foot skate ([`foot_skate_ratio`]), and a peak acceleration
/// ([`max_acceleration`]) at most [`LOOK_SLACK`] above the larger of the floored
/// motion's and capture's walks' ([`CAPTURE_MAX_ACCELERATION`]). Locks that pin a crawl's
/// dragging feet into the skate band, or jerk a leg towards an out-of-reach hold, are given up.
fn locks_help(floored: &[Pose], locked: &[Pose]) -> bool {
    let acceleration_bar = (1.0 + LOOK_SLACK) * max_acceleration(floored).max(CAPTURE_MAX_ACCELERATION);
    foot_skate_ratio(locked) <= foot_skate_ratio(floored) && max_acceleration(locked) <= acceleration_bar
}

/// The largest fraction in [0, `at_most`] of a leg's correction whose solve (`solve(fraction)`
/// gives the input leg and the solved one) leaves its knee, ankle and toe no lower than the
/// floor y = 0 or, for a joint already below it, than where it was (bisection, 1 mm slack;
/// `at_most` itself when it is safe, 0 when nothing is).
fn floor_safe_fraction(solve: impl Fn(f64) -> (Leg, LegSolution), at_most: f64) -> f64 {
    let safe = |fraction: f64| {
        let (leg, solved) = solve(fraction);
        [(leg.knee, solved.leg.knee), (leg.ankle, solved.leg.ankle), (leg.toe, solved.leg.toe)]
            .iter()
            .all(|(was, now)| now.y >= was.y.min(0.0) - FLOOR_SLACK_M)
    };
    if safe(at_most) {
        return at_most;
    }
    let (mut lo, mut hi) = (0.0, at_most);
    for _ in 0..10 {
        let mid = 0.5 * (lo + hi);
        if safe(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// `values` lowered so that no two neighbours differ by more than `step`: each value becomes
/// the least of `v_k + step·|t − k|` over all k (two passes), so a dip is approached and left
/// along ramps instead of in one frame.
fn ease_down(values: &[f64], step: f64) -> Vec<f64> {
    let mut out = values.to_vec();
    for t in 1..out.len() {
        out[t] = out[t].min(out[t - 1] + step);
    }
    for t in (0..out.len().saturating_sub(1)).rev() {
        out[t] = out[t].min(out[t + 1] + step);
    }
    out
}

/// Counters of [`foot_lock`] for its report.
#[derive(Debug, Clone, Copy, Default)]
struct Counts {
    shortened: usize,
    unreachable: usize,
    held_above_floor: usize,
}

/// The figures of a clean-up from `before` to `after` (`floor` is the floor height, the
/// lowering and the largest raise, m); `locked` is `None` when it did not run.
fn report(
    before: &[Pose],
    after: &[Pose],
    (floor_m, lowered_m, raised_m): (f64, f64, f64),
    locked: Option<[Vec<Range<usize>>; 4]>,
    counts: Counts,
) -> FootLockReport {
    let displacements: Vec<f64> =
        before.iter().zip(after).flat_map(|(a, b)| (0..NUM_JOINTS).map(move |j| (a[j] - b[j]).length())).collect();
    let max_bone_length_change_m = before
        .iter()
        .zip(after)
        .flat_map(|(a, b)| bone_lengths(a).into_iter().zip(bone_lengths(b)).map(|(x, y)| (x - y).abs()))
        .fold(0.0, f64::max);
    let enabled = locked.is_some();
    let mut segments = locked.unwrap_or_default();
    FootLockReport {
        enabled,
        floor_m,
        lowered_m,
        raised_m,
        contacts: std::array::from_fn(|k| {
            let segments = std::mem::take(&mut segments[k]);
            JointContacts { joint: CONTACT_JOINTS[k], locked_frames: segments.iter().map(Range::len).sum(), segments }
        }),
        shortened: counts.shortened,
        unreachable: counts.unreachable,
        held_above_floor: counts.held_above_floor,
        max_displacement_m: displacements.iter().copied().fold(0.0, f64::max),
        mean_displacement_m: crate::numeric::mean(displacements.iter().copied()),
        skate_before: foot_skate_ratio(before),
        skate_after: foot_skate_ratio(after),
        max_bone_length_change_m,
        undone_for: Vec::new(),
        locks_given_up: false,
    }
}
