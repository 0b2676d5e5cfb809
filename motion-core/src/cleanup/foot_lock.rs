//! Foot locking (Kovar, Schreiner & Gleicher 2002, "Footskate cleanup for motion capture
//! editing"): each contact of a foot joint gets one horizontal position, held over the contact,
//! and one lift that puts it on the floor; a correction track moves the joint there and eases
//! back to the original motion over a few frames on either side.

use std::ops::Range;

use glam::DVec3;

use crate::skeleton::smoothstep;

/// Where one joint is held during one contact.
#[derive(Debug, Clone, PartialEq)]
pub struct Lock {
    /// The contact's frames (half-open).
    pub frames: Range<usize>,
    /// The held horizontal position (x, z), m: the joint's mean over the contact.
    pub x_m: f64,
    /// See [`Lock::x_m`].
    pub z_m: f64,
    /// Raised by this over the whole contact, m, keeping its own small vertical motion (a heel
    /// rising before the foot leaves): what brings the joint's median height over the contact
    /// within the tolerance of its standing height (0 when it is already, or when no standing
    /// height is given).
    pub lift_m: f64,
}

impl Lock {
    /// The lock of `track` (one joint's positions, m) over `frames` (non-empty, in range),
    /// placing the joint's median height within `tolerance_m` of `standing_m` when given.
    pub fn new(track: &[DVec3], frames: Range<usize>, standing_m: Option<f64>, tolerance_m: f64) -> Lock {
        let span = &track[frames.clone()];
        let mean = span.iter().copied().sum::<DVec3>() / span.len().max(1) as f64;
        let mut heights: Vec<f64> = span.iter().map(|v| v.y).collect();
        heights.sort_by(f64::total_cmp);
        let median = heights.get(heights.len() / 2).copied().unwrap_or(0.0);
        let lift_m = standing_m.map_or(0.0, |h| {
            let off = h - median;
            off - off.clamp(-tolerance_m, tolerance_m)
        });
        Lock { frames, x_m: mean.x, z_m: mean.z, lift_m }
    }

    /// The offset that holds the joint, found at `at`, m.
    fn offset(&self, at: DVec3) -> DVec3 {
        DVec3::new(self.x_m - at.x, self.lift_m, self.z_m - at.z)
    }
}

/// The steadiest stretch of a contact: the longest run of `frames`, grown from its slowest
/// frame, over which `track` stays within `max_offset_m` (horizontally) of the run's mean, so
/// that holding the joint at that mean moves it by at most `max_offset_m`. The whole contact
/// when it already fits; `frames` is non-empty and in range.
///
/// A generated stance foot that slides farther than a foot's length is not planted; holding it
/// at the mean of the whole slide drags the leg by half the slide (28–66 cm on DNO outputs,
/// `fixtures/results/README.md`) and makes a stride the network never drew. Its steadiest part
/// is held instead, and the rest of the contact is left as generated.
pub fn steadiest(track: &[DVec3], frames: Range<usize>, max_offset_m: f64) -> Range<usize> {
    let flat = |t: usize| DVec3::new(track[t].x, 0.0, track[t].z);
    let mean = |r: &Range<usize>| r.clone().map(flat).sum::<DVec3>() / r.len() as f64;
    let fits = |r: &Range<usize>| {
        let hold = mean(r);
        r.clone().all(|t| (flat(t) - hold).length() <= max_offset_m)
    };
    if fits(&frames) {
        return frames;
    }
    // Horizontal speed per frame in whole mm per frame (central differences, one-sided at the
    // ends); among equally slow frames the one nearest the contact's middle.
    let speed = |t: usize| {
        let (a, b) = (t.saturating_sub(1).max(frames.start), (t + 1).min(frames.end - 1));
        ((flat(b) - flat(a)).length() / (b - a).max(1) as f64 * 1000.0).round()
    };
    let middle = (frames.start + frames.end - 1) as f64 / 2.0;
    let key = |t: usize| (speed(t), (t as f64 - middle).abs());
    let slowest = frames
        .clone()
        .min_by(|&a, &b| {
            let (ka, kb) = (key(a), key(b));
            ka.0.total_cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
        })
        .unwrap_or(frames.start);
    let mut run = slowest..slowest + 1;
    loop {
        let left = (run.start > frames.start).then(|| run.start - 1..run.end).filter(|r| fits(r));
        let right = (run.end < frames.end).then(|| run.start..run.end + 1).filter(|r| fits(r));
        run = match (left, right) {
            (Some(l), Some(r)) => {
                // Grow towards the frame nearer the current hold.
                let hold = mean(&run);
                if (flat(l.start) - hold).length() <= (flat(r.end - 1) - hold).length() + 1e-9 {
                    l
                } else {
                    r
                }
            }
            (Some(l), None) => l,
            (None, Some(r)) => r,
            (None, None) => return run,
        };
    }
}

/// How far the joint is moved in one frame and how firmly it is held.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Correction {
    /// Added to the joint's original position, m.
    pub offset: DVec3,
    /// 1 inside a contact, easing to 0 over the blend frames, 0 elsewhere.
    pub weight: f64,
}

/// How a lock eases in before and out after its contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Easing {
    /// At least this many frames, ...
    pub min_frames: usize,
    /// ... and enough that the easing moves the joint by at most this much per frame at its
    /// steepest, m: a large offset is let go of slowly rather than snapped back.
    pub max_step_m: f64,
}

impl Easing {
    /// Frames over which an offset of `length_m` eases: the least `n ≥ min_frames` with
    /// `1.5·length/(n + 1) ≤ max_step_m` (the steepest step of the smoothstep, see [`ease`]).
    fn frames(&self, length_m: f64) -> usize {
        let needed = (1.5 * length_m / self.max_step_m.max(f64::MIN_POSITIVE)).ceil() - 1.0;
        self.min_frames.max(needed.min(1e6) as usize)
    }
}

/// Weight of a lock `k ≥ 1` frames outside its contact when it eases over `frames`:
/// `smoothstep(1 − k/(frames + 1))`, so over 3 frames 0.84, 0.5, 0.16, then 0.
fn ease(k: usize, frames: usize) -> f64 {
    smoothstep(1.0 - k as f64 / (frames + 1) as f64)
}

/// The correction of one joint per frame: inside a contact the offset to its lock; between
/// contacts the offsets at the neighbouring contacts' ends, each eased out as `easing` says
/// (normalised where the two eases overlap, so a short gap moves smoothly from one lock to the
/// next). `locks` are in frame order and do not overlap.
pub fn corrections(track: &[DVec3], locks: &[Lock], easing: &Easing) -> Vec<Correction> {
    let mut out = vec![Correction::default(); track.len()];
    for lock in locks {
        for t in lock.frames.clone() {
            out[t] = Correction { offset: lock.offset(track[t]), weight: 1.0 };
        }
    }
    // Each gap, including the ones before the first and after the last contact.
    let ends = locks.iter().map(|l| Some((l.frames.end - 1, l.offset(track[l.frames.end - 1]))));
    let starts = locks.iter().map(|l| Some((l.frames.start, l.offset(track[l.frames.start]))));
    for (before, after) in std::iter::once(None).chain(ends).zip(starts.chain(std::iter::once(None))) {
        let from = before.map_or(0, |(e, _)| e + 1);
        let to = after.map_or(track.len(), |(s, _)| s);
        for (t, slot) in out.iter_mut().enumerate().take(to).skip(from) {
            let a = before.map(|(e, offset)| (ease(t - e, easing.frames(offset.length())), offset));
            let b = after.map(|(s, offset)| (ease(s - t, easing.frames(offset.length())), offset));
            let (weight, sum) = [a, b]
                .into_iter()
                .flatten()
                .fold((0.0, DVec3::ZERO), |(w, sum), (wi, offset)| (w + wi, sum + wi * offset));
            *slot = if weight > 1.0 {
                Correction { offset: sum / weight, weight: 1.0 }
            } else {
                Correction { offset: sum, weight }
            };
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three frames of easing for offsets up to 0.5 m.
    const THREE: Easing = Easing { min_frames: 3, max_step_m: 0.5 };

    /// Sliding along +z at 1 m/s, bobbing ±1 cm about 1 cm up.
    fn line(frames: usize) -> Vec<DVec3> {
        (0..frames).map(|t| DVec3::new(0.0, 0.01 + 0.01 * (t as f64).sin(), 0.05 * t as f64)).collect()
    }

    #[test]
    fn a_lock_is_the_mean_horizontal_position_with_the_median_height_on_the_floor() {
        let track = line(10);
        let lock = Lock::new(&track, 2..5, Some(0.02), 0.0);
        assert!(lock.x_m == 0.0 && (lock.z_m - 0.15).abs() < 1e-12, "{lock:?}");
        // Heights over frames 2..5: 0.01 + 0.01·sin(2, 3, 4); the median is sin 3's.
        let median = 0.01 + 0.01 * 3f64.sin();
        assert!((lock.lift_m - (0.02 - median)).abs() < 1e-12);
        assert_eq!(Lock::new(&track, 2..5, None, 0.0).lift_m, 0.0);
        // Within a tolerance of the standing height nothing is lifted; beyond it, up to it.
        assert_eq!(Lock::new(&track, 2..5, Some(0.02), 0.01).lift_m, 0.0);
        assert!((Lock::new(&track, 2..5, Some(0.03), 0.01).lift_m - (0.02 - median)).abs() < 1e-12);
        assert!((Lock::new(&track, 2..5, Some(-0.01), 0.01).lift_m - (-median)).abs() < 1e-12);
        let held = track[3] + lock.offset(track[3]);
        assert!((held - DVec3::new(0.0, track[3].y + lock.lift_m, 0.15)).length() < 1e-12);
    }

    #[test]
    fn a_slide_beyond_the_cap_keeps_only_its_steadiest_stretch() {
        // Slides 5 cm per frame, except frames 10..14, which stand still at z = 0.5.
        let track: Vec<DVec3> =
            (0..24usize).map(|t| DVec3::new(0.0, 0.0, 0.05 * (t.min(10) + t.saturating_sub(14)) as f64)).collect();
        // The whole contact fits a generous cap ...
        assert_eq!(steadiest(&track, 0..24, 1.0), 0..24);
        // ... a 15 cm cap keeps the standstill and the frames around it that stay within 15 cm
        // of the held point.
        let run = steadiest(&track, 0..24, 0.15);
        assert!(run.contains(&10) && run.contains(&14), "{run:?}");
        let mean = run.clone().map(|t| track[t]).sum::<DVec3>() / run.len() as f64;
        assert!(run.clone().all(|t| (track[t] - mean).length() <= 0.15), "{run:?}");
        assert!(run.len() < 24 && run.len() >= 9, "{run:?}");
        // A single frame always fits.
        assert_eq!(steadiest(&track, 3..4, 0.0), 3..4);
    }

    #[test]
    fn corrections_hold_the_lock_and_ease_out_without_jumps() {
        let track = line(20);
        let lock = Lock::new(&track, 8..12, Some(0.0), 0.0);
        let c = corrections(&track, std::slice::from_ref(&lock), &THREE);
        for t in 8..12 {
            let held = track[t] + c[t].offset;
            assert!((held.x, held.z) == (lock.x_m, lock.z_m) && held.y == track[t].y + lock.lift_m, "frame {t}");
            assert_eq!(c[t].weight, 1.0);
        }
        // Eased over 3 frames on each side, nothing beyond.
        for t in (0..5).chain(15..20) {
            assert_eq!(c[t], Correction::default(), "frame {t}");
        }
        assert!((c[12].weight - 0.84375).abs() < 1e-12 && (c[14].weight - 0.15625).abs() < 1e-12);
        assert!((c[12].offset - 0.84375 * lock.offset(track[11])).length() < 1e-12);
        assert!((c[7].offset - 0.84375 * lock.offset(track[8])).length() < 1e-12);
    }

    #[test]
    fn a_short_gap_moves_from_one_lock_to_the_next() {
        let track = line(12);
        let locks = [Lock::new(&track, 0..4, Some(0.0), 0.0), Lock::new(&track, 6..12, Some(0.0), 0.0)];
        let c = corrections(&track, &locks, &THREE);
        // Frames 4 and 5: both eases overlap (0.84 + 0.5 > 1): normalised, fully held.
        for t in [4, 5] {
            assert_eq!(c[t].weight, 1.0);
        }
        let (from, to) = (locks[0].offset(track[3]), locks[1].offset(track[6]));
        assert!((c[4].offset - (0.84375 * from + 0.5 * to) / 1.34375).length() < 1e-12);
        assert_eq!(corrections(&track, &[], &THREE), vec![Correction::default(); 12]);
    }

    #[test]
    fn a_large_offset_eases_out_no_faster_than_the_step_limit() {
        let easing = Easing { min_frames: 3, max_step_m: 0.02 };
        assert_eq!(easing.frames(0.01), 3);
        // 1.5 · 0.3 / 0.02 = 22.5: 22 frames.
        assert_eq!(easing.frames(0.3), 22);
        // A foot held 30 cm behind its slide (1 m/s) is let go of over 22 frames.
        let track = line(60);
        let lock = Lock { frames: 0..7, x_m: 0.0, z_m: 0.0, lift_m: 0.0 };
        let c = corrections(&track, std::slice::from_ref(&lock), &easing);
        assert!((c[6].offset.z + 0.3).abs() < 1e-12);
        assert!(c[28].weight > 0.0 && c[29] == Correction::default());
        for t in 6..30 {
            let step = (c[t + 1].offset - c[t].offset).length();
            assert!(step <= 0.02 + 1e-12, "frame {t}: {step}");
        }
    }
}
