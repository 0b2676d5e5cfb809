//! Events in a scalar signal, counted with hysteresis.

use crate::program::EventRegion;

/// Events in a scalar signal (one value per frame): entries into the event region (below or
/// above its threshold θ), each counted once until the signal goes back beyond the hysteresis
/// band (`θ + hysteresis` for `below`, `θ − hysteresis` for `above`); an event under way at the
/// first frame counts. A clap is the wrists coming within θ of each other; wrists that stop at
/// 0.17 m with θ = 0.06 m make none. The one definition of an event count: the `events`
/// constraint's check uses it, and so does its error, with the gradient of the soft form
/// ([`crate::constraints::soft_event_count`]).
pub fn event_count(values: &[f64], region: EventRegion, hysteresis: f64) -> usize {
    // Signed depth into the region: > 0 inside, < −hysteresis beyond the band.
    let depth = |v: f64| match region {
        EventRegion::Below(theta) => theta - v,
        EventRegion::Above(theta) => v - theta,
    };
    let mut armed = true;
    let mut count = 0;
    for &v in values {
        if armed && depth(v) > 0.0 {
            count += 1;
            armed = false;
        } else if !armed && depth(v) < -hysteresis {
            armed = true;
        }
    }
    count
}
