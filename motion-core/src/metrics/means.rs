//! The figures of a set of motions, measured once for every report: a run's report
//! ([`crate::evaluation`]), the benchmark tables and the prior's report ([`crate::quality`]) all
//! read a [`MetricMeans`].

use serde::{Deserialize, Serialize};

use super::body::{
    bone_length_range, foot_skate_ratio, ground_penetration, hands_raised, head_neck_incorrect, max_acceleration,
    mean_foot_acceleration, root_travel,
};
use super::gait::{
    airborne_frames, heading_change_rad, longest_flight_s, mean_acceleration, pace, spike_frames, stance_toe_height,
    toe_flicker, FLOATING_FLIGHT_S,
};
use crate::numeric;
use crate::skeleton::{Joint, Pose};

/// Means of the metrics over a set of motions (worst cases where the name says so). Every
/// figure is 0 for an empty set.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MetricMeans {
    /// Leg alternations (steps) per second ([`pace`]).
    pub pace_steps_per_s: f64,
    /// Mean coefficient of variation of the step intervals, over the motions that have one
    /// ([`pace`]); `None` when none has.
    pub pace_interval_cv: Option<f64>,
    /// Fraction of frames whose toe heights zig-zag by more than 1 cm both ways ([`toe_flicker`];
    /// capture walks: about 0.1).
    pub toe_flicker: f64,
    /// Mean joint acceleration, m/frame² ([`mean_acceleration`]; capture walks: about 0.011).
    pub mean_acceleration: f64,
    /// Max joint acceleration, m/frame²: the mean over motions of each one's maximum
    /// ([`max_acceleration`], ProgMoGen's Max Acc).
    pub max_acceleration: f64,
    /// Mean acceleration of the two foot joints, m/frame² ([`mean_foot_acceleration`]).
    pub foot_acceleration: f64,
    /// Foot skate ratio ([`foot_skate_ratio`], GMD's).
    pub foot_skate_ratio: f64,
    /// Largest bone-length range within any motion, m (worst over motions).
    pub bone_length_range_m: f64,
    /// The deepest any joint goes under the floor y = 0 in any motion, m (worst over motions).
    pub max_under_floor_m: f64,
    /// Median height of the lower toe, m ([`stance_toe_height`]; capture walks: 1.5–2 cm): a
    /// floating figure shows here.
    pub stance_toe_height_m: f64,
    /// Fraction of motions airborne for at least 2 frames ([`airborne_frames`]).
    pub airborne_share: f64,
    /// Fraction of motions with a flight longer than [`FLOATING_FLIGHT_S`] (floating).
    pub floating_share: f64,
    /// The longest flight of any motion, s ([`longest_flight_s`]; worst over motions).
    pub longest_flight_s: f64,
    /// Mean signed turn, degrees (positive: left; [`heading_change_rad`]).
    pub turn_deg: f64,
    /// Fraction of motions turning more than [`TURN_DEG`] left.
    pub turn_left_share: f64,
    /// Fraction of motions turning more than [`TURN_DEG`] right.
    pub turn_right_share: f64,
    /// Mean number of one-frame spikes per motion ([`spike_frames`]).
    pub spikes: f64,
    /// Mean head height, m.
    pub head_height_m: f64,
    /// Horizontal pelvis travel from first to last frame, m ([`root_travel`]).
    pub travel_m: f64,
    /// Fraction of motions with a hand above the shoulder in at least half of the frames
    /// ([`hands_raised`]).
    pub hands_raised_rate: f64,
    /// Fraction of head–neck lengths at frames 0, L//2, L−1 outside
    /// [`super::body::HEAD_NECK_VALID_M`] ([`head_neck_incorrect`]).
    pub head_neck_incorrect_ratio: f64,
    /// Motions measured.
    pub count: usize,
}

/// A turn of more than this counts as turning that way, degrees.
pub const TURN_DEG: f64 = 30.0;

impl MetricMeans {
    /// Means over motions.
    pub fn of(motions: &[Vec<Pose>]) -> Self {
        let n = motions.len().max(1) as f64;
        let mean = |f: &dyn Fn(&[Pose]) -> f64| numeric::mean(motions.iter().map(|m| f(m)));
        let worst = |f: &dyn Fn(&[Pose]) -> f64| motions.iter().map(|m| f(m)).fold(0.0, f64::max);
        let share = |f: &dyn Fn(&[Pose]) -> bool| motions.iter().filter(|m| f(m)).count() as f64 / n;
        let turn = |m: &[Pose]| heading_change_rad(m).to_degrees();
        let paces: Vec<(f64, Option<f64>)> = motions.iter().map(|m| pace(m)).collect();
        let cvs: Vec<f64> = paces.iter().filter_map(|p| p.1).collect();
        let (bad, checked) =
            motions.iter().map(|m| head_neck_incorrect(m)).fold((0, 0), |(b, c), (b1, c1)| (b + b1, c + c1));
        Self {
            pace_steps_per_s: numeric::mean(paces.iter().map(|p| p.0)),
            pace_interval_cv: (!cvs.is_empty()).then(|| numeric::mean(cvs.iter().copied())),
            toe_flicker: mean(&toe_flicker),
            mean_acceleration: mean(&mean_acceleration),
            max_acceleration: mean(&max_acceleration),
            foot_acceleration: mean(&mean_foot_acceleration),
            foot_skate_ratio: mean(&foot_skate_ratio),
            bone_length_range_m: worst(&bone_length_range),
            max_under_floor_m: worst(&ground_penetration),
            stance_toe_height_m: mean(&stance_toe_height),
            airborne_share: share(&|m: &[Pose]| airborne_frames(m) >= 2),
            floating_share: share(&|m: &[Pose]| longest_flight_s(m) > FLOATING_FLIGHT_S),
            longest_flight_s: worst(&longest_flight_s),
            turn_deg: mean(&turn),
            turn_left_share: share(&|m: &[Pose]| turn(m) > TURN_DEG),
            turn_right_share: share(&|m: &[Pose]| turn(m) < -TURN_DEG),
            spikes: mean(&|m: &[Pose]| spike_frames(m) as f64),
            head_height_m: mean(&|m: &[Pose]| numeric::mean(m.iter().map(|p| p[Joint::Head.index()].y))),
            travel_m: mean(&root_travel),
            hands_raised_rate: share(&hands_raised),
            head_neck_incorrect_ratio: bad as f64 / checked.max(1) as f64,
            count: motions.len(),
        }
    }

    /// The name of the first figure that is NaN or infinite (`None` when all are finite).
    pub fn non_finite_figure(&self) -> Option<&'static str> {
        let figures = [
            ("pace", self.pace_steps_per_s),
            ("pace interval variation", self.pace_interval_cv.unwrap_or(0.0)),
            ("toe flicker", self.toe_flicker),
            ("mean acceleration", self.mean_acceleration),
            ("max acceleration", self.max_acceleration),
            ("foot acceleration", self.foot_acceleration),
            ("foot skate ratio", self.foot_skate_ratio),
            ("bone length range", self.bone_length_range_m),
            ("depth under the floor", self.max_under_floor_m),
            ("stance toe height", self.stance_toe_height_m),
            ("longest flight", self.longest_flight_s),
            ("turn", self.turn_deg),
            ("spikes", self.spikes),
            ("head height", self.head_height_m),
            ("travel", self.travel_m),
            ("head-neck ratio", self.head_neck_incorrect_ratio),
        ];
        figures.iter().find(|(_, v)| !v.is_finite()).map(|(name, _)| *name)
    }
}
