//! Motion quality metrics on joint positions at 20 fps, as ProgMoGen and DNO define them
//! (`reference/anchors.md` §3.7). Inputs are `[frames]` of [`Pose`]s in metres, y up, ground at
//! y = 0.
//!
//! [`Pose`]: crate::skeleton::Pose

mod body;
mod events;
mod gait;
mod means;

pub use body::{
    bone_length_range, foot_contact_ratio, foot_skate_ratio, ground_penetration, hand_hold, hands_raised,
    head_neck_incorrect, max_acceleration, mean_foot_acceleration, root_travel, HandHold, CAPTURE_FOOT_SKATE,
    CAPTURE_MAX_ACCELERATION, HEAD_NECK_REST_M, HEAD_NECK_VALID_M, LOOK_SLACK, SKATE_CONTACT_HEIGHT_M,
    SKATE_SPEED_M_PER_S,
};
pub use events::event_count;
pub use gait::{
    airborne_frames, alternation_frames, footfalls, heading_change_rad, longest_flight_s, longest_run,
    mean_acceleration, moving_pace, pace, spike_frames, stance_toe_height, step_count, toe_flicker, toe_separation,
    AIRBORNE_M, ALTERNATION_HYSTERESIS_M, FLICKER_M, FLOATING_FLIGHT_S, FOOTFALL_MIN_M, MOVING_M_PER_S,
    SPIKE_ACCELERATION_M, SWING_ENTER_M_PER_S, SWING_LEAVE_M_PER_S,
};
pub use means::{MetricMeans, TURN_DEG};
