//! Skill families: what a window of capture, or a generated motion, does, by measurement
//! (issue 40, item 4). A family names a skill (walk, run, turn left, ..., crawl); [`Family::holds`]
//! says whether a corpus window is an example of it (the report's held-out windows, the
//! trainer's family balance) and [`Family::detect`] whether a motion passes its action detector.
//!
//! A window's family is chosen by what its own motion does (the corpus tagger's [`MotionTags`]
//! and the caption rule's [`Action`]), plus the take's description for carrying and sitting,
//! whose motion alone does not say it.
//!
//! **Detectors** are measurements, not judgements by eye; each says whether one motion does
//! what its prompt asks (the thresholds are the issue's):
//! - sideways: the body travels more sideways than forwards (the tagger's travel direction);
//! - sneak/crouch: the mean pelvis height is at least 15 % below a standing body's;
//! - jump, hop on one foot: at least 2 frames airborne;
//! - one-leg balance: one foot more than 10 cm up while the other is down, for 2 s at a stretch;
//! - sit down: the first second stands (pelvis above the crouch line) and the last is seated
//!   (pelvis low, at knee height, still): a body seated throughout has not sat down;
//! - walk, run, crawl: the caption rule names the same action; walks also travel forwards, and
//!   runs step at a running cadence while they move ([`RUN_MIN_STEPS_PER_S`]);
//! - turns: at least [`TURN_MIN_DEG`](crate::corpus::tags::TURN_MIN_DEG) the asked way;
//! - carry: both hands held in front of the body at the pelvis or higher, a steady distance
//!   apart and without a walk's arm swing (`carries_in_front`): a box or a crate in both
//!   arms. Nothing in the joints says that a hanging hand holds a suitcase, so a one-handed
//!   carry does not pass.

use serde::Serialize;

use super::caption::Action;
use super::clips::{Corpus, CorpusWindow};
use super::skill::Skill;
use super::split::Split;
use super::tags::{standing_pelvis_height, MotionTags, TravelDirection};
use crate::metrics::{hand_hold, moving_pace};
use crate::skeleton::{Joint, Pose, FPS};

/// A skill family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Walking forwards.
    Walk,
    /// Running.
    Run,
    /// Walking and turning left.
    TurnLeft,
    /// Walking and turning right.
    TurnRight,
    /// Walking sideways.
    Sideways,
    /// Walking crouched.
    Sneak,
    /// Jumping with both feet.
    Jump,
    /// Hopping on one foot.
    HopOneFoot,
    /// Standing on one leg.
    Balance,
    /// Carrying something.
    Carry,
    /// Sitting down.
    SitDown,
    /// Crawling.
    Crawl,
}

/// Fraction of a standing body's pelvis height that a crouched walk stays below, at most.
pub const CROUCH_PELVIS_FRACTION: f64 = 0.85;
/// Shortest one-leg stance that passes the balance detector, s.
pub const BALANCE_MIN_S: f64 = 2.0;
/// Fewest leg alternations a second while moving ([`moving_pace`]) of a run. Running steps at
/// 2.5 a second and faster (the shipped DeepMimic run 2.5, the held-out CMU run windows
/// 3.9–5.0), walking at 2 or fewer (the DeepMimic walks 1.6). A body that covers more than
/// 2 m/s at a walking cadence bounds or glides in strides longer than a run's: it is not
/// running.
pub const RUN_MIN_STEPS_PER_S: f64 = 2.2;
/// Least distance of both wrists ahead of the pelvis in a two-handed carry, m ([`crate::metrics::HandHold::ahead_m`]).
/// The corpus's two walks carrying a box (ACCAD `B20_WalkWithBox`) hold them 0.20 and 0.34 m
/// ahead; hands hanging at the sides are 0.0–0.1 m ahead.
pub const CARRY_AHEAD_M: f64 = 0.15;
/// Largest spread of the wrists' distance in a two-handed carry, m ([`crate::metrics::HandHold::gap_spread_m`]):
/// 0.006 and 0.013 m in the box walks, where both hands hold one box.
pub const CARRY_GAP_SPREAD_M: f64 = 0.03;
/// Largest arm swing of a carry, m ([`crate::metrics::HandHold::swing_m`]): 0.04 and 0.05 m in the box walks,
/// 0.1–0.3 m in walks with free arms.
pub const CARRY_SWING_M: f64 = 0.06;

impl Family {
    /// Every family, in report order.
    pub const ALL: [Family; 12] = [
        Family::Walk,
        Family::Run,
        Family::TurnLeft,
        Family::TurnRight,
        Family::Sideways,
        Family::Sneak,
        Family::Jump,
        Family::HopOneFoot,
        Family::Balance,
        Family::Carry,
        Family::SitDown,
        Family::Crawl,
    ];

    /// Short name for tables and `--family`.
    pub fn name(self) -> &'static str {
        match self {
            Family::Walk => "walk",
            Family::Run => "run",
            Family::TurnLeft => "turn left",
            Family::TurnRight => "turn right",
            Family::Sideways => "sideways walk",
            Family::Sneak => "sneak/crouch walk",
            Family::Jump => "jump",
            Family::HopOneFoot => "hop on one foot",
            Family::Balance => "one-leg balance",
            Family::Carry => "carry",
            Family::SitDown => "sit down",
            Family::Crawl => "crawl",
        }
    }

    /// The family called `name` ([`Family::name`]); the error lists the names.
    pub fn from_name(name: &str) -> Result<Family, String> {
        Family::ALL.into_iter().find(|f| f.name() == name).ok_or_else(|| {
            let names: Vec<&str> = Family::ALL.iter().map(|f| f.name()).collect();
            format!("unknown family {name:?}; the families are: {}", names.join(", "))
        })
    }

    /// The prompts its samples are drawn for: a caption-like one and a paraphrase whose verbs
    /// and direction words the caption rules (`caption.rs`) never use ("someone strolls ahead"
    /// and "someone stands on one foot" are training captions).
    pub fn prompts(self) -> [&'static str; 2] {
        match self {
            Family::Walk => ["a person walks forward", "a woman ambles along at an easy pace"],
            Family::Run => ["a person runs forward", "a man sprints off into the distance"],
            Family::TurnLeft => ["a person walks and turns left", "someone ambles and veers off to their left"],
            Family::TurnRight => ["a person walks and turns right", "someone ambles and veers off to their right"],
            Family::Sideways => ["a person walks sideways to the left", "a man tiptoes sideways to his right"],
            Family::Sneak => ["a person sneaks forward crouching", "someone prowls along hunched over"],
            Family::Jump => ["a person jumps forward", "someone bounds onward with both feet"],
            Family::HopOneFoot => ["a person hops on one foot", "someone bounces along on a single leg"],
            Family::Balance => ["a person balances on one leg", "someone keeps one foot off the ground"],
            Family::Carry => ["a person carries a heavy box", "someone walks holding a suitcase"],
            Family::SitDown => ["a person sits down on a chair", "someone takes a seat"],
            Family::Crawl => {
                ["a person crawls forward on the ground", "a toddler scrambles across the floor on its knees"]
            }
        }
    }

    /// Whether the family is plain walking (forwards or turning), which prompts name loosely:
    /// "a man walks forwards" under a barrier that a crawl clears. The other families are the
    /// skills a prompt asks for, which retrieval looks for first and a sample is tried again
    /// without.
    pub fn is_walking(self) -> bool {
        matches!(self, Family::Walk | Family::TurnLeft | Family::TurnRight)
    }

    /// The family of the skill a prompt names, the most specific ([`Family::all_named_in`]'s
    /// first); `None` when it names none.
    pub fn named_in(prompt: &str) -> Option<Family> {
        Family::all_named_in(prompt).first().copied()
    }

    /// The families of the skills a prompt names, the most specific first: a crawl, a sit, a
    /// hop (a jump named by "hop") or else a jump, a run, a sideways walk ("side-steps" too), a
    /// crouch or a duck under something (the crouched walk), a one-leg balance, a carry, a turn
    /// to a named side, a walk. Read with the corpus's skill words ([`Skill::of`], and
    /// "carries", which take descriptions never say), so "walks to a chair and sits down" is a
    /// sit, then a walk.
    pub fn all_named_in(prompt: &str) -> Vec<Family> {
        let text = prompt.to_lowercase().replace('-', " ");
        let skills = Skill::of(&text);
        let names = |skill: Skill| skills.contains(&skill);
        let word = |w: &str| text.split(|c: char| !c.is_ascii_alphanumeric()).any(|x| x.starts_with(w));
        let turn = names(Skill::Turn);
        [
            (Family::Crawl, names(Skill::Crawl)),
            (Family::SitDown, names(Skill::Sit)),
            (Family::HopOneFoot, names(Skill::JumpHop) && word("hop")),
            (Family::Jump, names(Skill::JumpHop) && !word("hop")),
            (Family::Run, names(Skill::Run)),
            (Family::Sideways, names(Skill::Sideways)),
            (Family::Sneak, names(Skill::CrouchSneak) || names(Skill::Under)),
            (Family::Balance, names(Skill::Balance)),
            (Family::Carry, names(Skill::Carry) || word("carri")),
            (Family::TurnLeft, turn && word("left")),
            (Family::TurnRight, turn && word("right")),
            (Family::Walk, names(Skill::Walk)),
        ]
        .into_iter()
        .filter_map(|(family, named)| named.then_some(family))
        .collect()
    }

    /// The held-out (test-split) windows of `corpus` that are examples of the family
    /// ([`Family::holds`]), in corpus order.
    pub fn held_out<'a>(self, corpus: &'a Corpus) -> impl Iterator<Item = &'a CorpusWindow> + 'a {
        corpus.windows.iter().filter(move |w| {
            let clip = &corpus.clips[w.clip];
            clip.split == Split::Test && self.holds(corpus.window_joints(w), &w.tags, &clip.description)
        })
    }

    /// The family of a window (its poses and tags) of a take with this description: the first
    /// of [`Family::ALL`] that it is an example of ([`Family::holds`]), `None` for none.
    pub fn of(poses: &[Pose], tags: &MotionTags, description: &str) -> Option<Family> {
        Family::ALL.into_iter().find(|f| f.holds(poses, tags, description))
    }

    /// Whether a window (its poses and tags) of a take with this description is an example of
    /// the family.
    pub fn holds(self, poses: &[Pose], tags: &MotionTags, description: &str) -> bool {
        let action = Action::of(tags);
        let straight = tags.turn_left().is_none();
        match self {
            Family::Walk => {
                action == Action::Walk
                    && straight
                    && tags.direction == Some(TravelDirection::Forwards)
                    && !tags.crouched
            }
            Family::Run => action == Action::Run,
            Family::TurnLeft => action == Action::Walk && tags.turn_left() == Some(true),
            Family::TurnRight => action == Action::Walk && tags.turn_left() == Some(false),
            Family::Sideways => matches!(action, Action::Walk | Action::Sneak) && sideways(tags),
            Family::Sneak => action == Action::Sneak,
            Family::Jump => action == Action::Jump,
            Family::HopOneFoot => action == Action::HopOneFoot,
            Family::Balance => action == Action::Balance,
            Family::Carry => Skill::Carry.named_by(description) && matches!(action, Action::Walk | Action::Stand),
            Family::SitDown => Skill::Sit.named_by(description) && self.detect(poses),
            Family::Crawl => action == Action::Crawl,
        }
    }

    /// Whether the family's skill may happen in a window (its poses and tags) of a take with
    /// this description, as retrieval asks: the window is an example of it ([`Family::holds`]),
    /// or, for sitting down, it is any window of a take that says it sits. A window that holds
    /// a whole sit-down (standing its first second, seated its last) is rare, since the
    /// windows' fixed starts cut most sit-downs; a crop of a sitting take that stands at its
    /// start and sits at its end is one, and `C_R` finds it.
    pub fn happens_in(self, poses: &[Pose], tags: &MotionTags, description: &str) -> bool {
        let in_a_sitting_take = self == Family::SitDown && Skill::Sit.named_by(description);
        in_a_sitting_take || self.holds(poses, tags, description)
    }

    /// The family's bit in [`Families`]: its place in [`Family::ALL`].
    fn bit(self) -> u16 {
        1 << self as u16
    }

    /// What the detector checks, for the report.
    pub fn detector(self) -> &'static str {
        match self {
            Family::Walk => "walks forwards",
            Family::Run => "runs (> 2 m/s, ≥ 2.2 steps/s moving)",
            Family::TurnLeft => "turns ≥ 45° left",
            Family::TurnRight => "turns ≥ 45° right",
            Family::Sideways => "travels more sideways than forwards",
            Family::Sneak => "pelvis ≥ 15 % below standing",
            Family::Jump | Family::HopOneFoot => "airborne ≥ 2 frames",
            Family::Balance => "one foot up ≥ 2 s",
            Family::Carry => "both hands held in front, steady",
            Family::SitDown => "stands in the first second, seated in the last",
            Family::Crawl => "crawls",
        }
    }

    /// Whether a motion (joints on the floor, 20 fps) passes the family's detector.
    pub fn detect(self, poses: &[Pose]) -> bool {
        let tags = MotionTags::measure(poses);
        let action = Action::of(&tags);
        match self {
            Family::Walk => action == Action::Walk && tags.direction == Some(TravelDirection::Forwards),
            Family::Run => action == Action::Run && moving_pace(poses) >= RUN_MIN_STEPS_PER_S,
            Family::TurnLeft => tags.turn_left() == Some(true),
            Family::TurnRight => tags.turn_left() == Some(false),
            Family::Sideways => sideways(&tags),
            Family::Sneak => mean_pelvis_height(poses) <= CROUCH_PELVIS_FRACTION * standing_pelvis_height(),
            Family::Jump | Family::HopOneFoot => tags.airborne(),
            Family::Balance => tags.one_foot_up_s >= BALANCE_MIN_S,
            Family::Carry => carries_in_front(poses),
            Family::SitDown => {
                let second = (FPS as usize).min(poses.len());
                let stands = mean_pelvis_height(&poses[..second]) > CROUCH_PELVIS_FRACTION * standing_pelvis_height();
                stands && MotionTags::measure(&poses[poses.len() - second..]).sitting
            }
            Family::Crawl => action == Action::Crawl,
        }
    }
}

/// A set of families: what a window is an example of (a crouched sideways walk is a sneak and a
/// sideways walk at once).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Families(u16);

impl Families {
    /// The families whose skill happens in a window (its poses and tags) of a take with this
    /// description ([`Family::happens_in`]).
    pub fn happening_in(poses: &[Pose], tags: &MotionTags, description: &str) -> Self {
        Family::ALL.into_iter().filter(|f| f.happens_in(poses, tags, description)).collect()
    }

    /// Whether `family` is in the set.
    pub fn contains(self, family: Family) -> bool {
        self.0 & family.bit() != 0
    }
}

impl FromIterator<Family> for Families {
    fn from_iter<I: IntoIterator<Item = Family>>(families: I) -> Self {
        Families(families.into_iter().fold(0, |bits, f| bits | f.bit()))
    }
}

/// Mean pelvis height over the frames, m (0 for none).
fn mean_pelvis_height(poses: &[Pose]) -> f64 {
    crate::numeric::mean(poses.iter().map(|p| p[Joint::Pelvis.index()].y))
}

/// Whether both hands are held in front of the body, at the pelvis or higher, a steady distance
/// apart and without swinging ([`CARRY_AHEAD_M`], [`CARRY_GAP_SPREAD_M`], [`CARRY_SWING_M`]):
/// how a body carries a box in both arms.
fn carries_in_front(poses: &[Pose]) -> bool {
    hand_hold(poses).is_some_and(|h| {
        h.ahead_m >= CARRY_AHEAD_M
            && h.above_pelvis_m >= 0.0
            && h.gap_spread_m <= CARRY_GAP_SPREAD_M
            && h.swing_m <= CARRY_SWING_M
    })
}

fn sideways(tags: &MotionTags) -> bool {
    matches!(tags.direction, Some(TravelDirection::SidewaysLeft | TravelDirection::SidewaysRight))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::corpus::prepare::put_on_floor;
    use crate::skeleton::rest_pose;

    #[test]
    fn every_family_has_two_prompts_and_a_name() {
        for f in Family::ALL {
            assert!(f.prompts().iter().all(|p| !p.is_empty()) && f.prompts()[0] != f.prompts()[1], "{f:?}");
        }
        let names: std::collections::BTreeSet<_> = Family::ALL.iter().map(|f| f.name()).collect();
        assert_eq!(names.len(), Family::ALL.len());
    }

    /// The rare-skill suite's prompts (`fixtures/tasks/skill_*.json`) and Table 6's name the
    /// skill a person would read in them.
    #[test]
    fn prompts_name_the_most_specific_skill() {
        let cases = [
            ("a person crawls forward on hands and knees", Some(Family::Crawl)),
            ("a person walks to a chair and sits down", Some(Family::SitDown)),
            ("a person hops forward on the right foot", Some(Family::HopOneFoot)),
            ("a person jumps forward onto a step", Some(Family::Jump)),
            ("a person runs forward and jumps over a hurdle", Some(Family::Jump)),
            ("a man sprints off into the distance", Some(Family::Run)),
            ("a person side-steps to the left", Some(Family::Sideways)),
            ("a person ducks under a barrier while walking forward", Some(Family::Sneak)),
            ("a person balances on one leg", Some(Family::Balance)),
            ("a person carries a box forward", Some(Family::Carry)),
            ("a person walks and turns left", Some(Family::TurnLeft)),
            ("a person walks forward", Some(Family::Walk)),
            ("a person reaches up high with a hand again and again", None),
        ];
        for (prompt, family) in cases {
            assert_eq!(Family::named_in(prompt), family, "{prompt}");
        }
        assert_eq!(Family::all_named_in("a man runs forwards and jumps over an obstacle"), [Family::Jump, Family::Run]);
        assert_eq!(Family::all_named_in("a person walks to a chair and sits down"), [Family::SitDown, Family::Walk]);
        // Every family's own caption-like prompt names it.
        for f in Family::ALL {
            assert_eq!(Family::named_in(f.prompts()[0]), Some(f), "{}", f.prompts()[0]);
        }
    }

    #[test]
    fn a_set_of_families_holds_each_family_by_its_place() {
        for (k, f) in Family::ALL.into_iter().enumerate() {
            assert_eq!(f as usize, k, "{f:?} is out of place in Family::ALL");
            let one: Families = [f].into_iter().collect();
            assert!(Family::ALL.into_iter().all(|g| one.contains(g) == (g == f)));
        }
        let none = Families::default();
        assert!(Family::ALL.into_iter().all(|f| !none.contains(f)));
    }

    #[test]
    fn sitting_down_may_happen_in_any_window_of_a_take_that_sits() {
        let standing = put_on_floor(&vec![rest_pose(); 40]);
        let tags = MotionTags::measure(&standing);
        assert!(!Family::SitDown.holds(&standing, &tags, "sit down and get up"));
        assert!(Family::SitDown.happens_in(&standing, &tags, "sit down and get up"));
        assert!(!Family::SitDown.happens_in(&standing, &tags, "stand still"));
        assert!(!Families::happening_in(&standing, &tags, "stand still").contains(Family::SitDown));
        // Other families happen where they hold.
        let sitting = sitting_down(40, 20, 60);
        let sat = MotionTags::measure(&sitting);
        assert!(Family::SitDown.holds(&sitting, &sat, "sit on a chair"));
        assert!(Family::ALL
            .into_iter()
            .all(|f| f.happens_in(&standing, &tags, "walk") == f.holds(&standing, &tags, "walk")));
    }

    /// A body lowered onto a seat at knee height over `lower` frames, after `stand` frames standing,
    /// then seated for `seated` frames.
    fn sitting_down(stand: usize, lower: usize, seated: usize) -> Vec<Pose> {
        let rest = put_on_floor(&[rest_pose()])[0];
        let knees = 0.5 * (rest[Joint::LeftKnee.index()].y + rest[Joint::RightKnee.index()].y);
        let drop = rest[Joint::Pelvis.index()].y - knees;
        let legs =
            [Joint::LeftKnee, Joint::RightKnee, Joint::LeftAnkle, Joint::RightAnkle, Joint::LeftFoot, Joint::RightFoot];
        (0..stand + lower + seated)
            .map(|t| {
                let down = drop * (t.saturating_sub(stand) as f64 / lower.max(1) as f64).min(1.0);
                let mut p = rest;
                for j in Joint::ALL.into_iter().filter(|j| !legs.contains(j)) {
                    p[j.index()].y -= down;
                }
                p
            })
            .collect()
    }

    /// The shipped DeepMimic run (real capture, 2.5 steps/s) runs; the same run played at half
    /// its cadence while covering the same ground (bounding strides at a walking cadence) does
    /// not, though the caption rule calls both a run (faster than 2 m/s).
    #[test]
    fn a_run_steps_at_a_running_cadence() {
        use crate::import::{deepmimic::shipped, resample};
        let clip = shipped::clip("humanoid3d_run.txt");
        let run = put_on_floor(&resample(&clip, 1.0, Some(6.0)));
        let slow = put_on_floor(&resample(&clip, 0.5, Some(6.0)));
        // Slowed down, then carried forwards by as much again: the run's speed at half its cadence.
        let start = slow[0][Joint::Pelvis.index()];
        let bounding: Vec<Pose> = slow
            .iter()
            .map(|p| {
                let shift = p[Joint::Pelvis.index()] - start;
                let mut q = *p;
                for j in q.iter_mut() {
                    j.x += shift.x;
                    j.z += shift.z;
                }
                q
            })
            .collect();
        for (motion, runs) in [(&run, true), (&bounding, false)] {
            let tags = MotionTags::measure(motion);
            assert_eq!(Action::of(&tags), Action::Run, "speed {}", tags.speed_m_per_s);
            assert_eq!(Family::Run.detect(motion), runs, "{:.2} steps/s", moving_pace(motion));
        }
    }

    #[test]
    fn sitting_down_stands_first_and_ends_seated() {
        let sit = Family::SitDown;
        assert!(sit.detect(&sitting_down(40, 20, 60)));
        // Seated from the first frame: it never sat down.
        assert!(!sit.detect(&sitting_down(0, 1, 120)));
        // Standing throughout, or still on the way down at the end.
        assert!(!sit.detect(&sitting_down(120, 1, 0)));
        assert!(!sit.detect(&sitting_down(90, 30, 0)));
    }
}
