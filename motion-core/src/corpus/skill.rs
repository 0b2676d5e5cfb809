//! Skill families named by a take's description (`walk sideways and turn`, `Sneaking`,
//! `balance on one leg`): how the corpus is counted per skill (`mogen data stats`) and which
//! take a per-skill picture shows. A description may name several skills. This is what CMU
//! says of a whole take; what each window does is measured by [`super::tags`].

use serde::{Deserialize, Serialize};

/// A family of skills, named by words of a take's description.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Skill {
    /// Walking, strolling, marching.
    Walk,
    /// Turning, veering.
    Turn,
    /// Running, jogging.
    Run,
    /// Jumping, hopping, leaping.
    JumpHop,
    /// Walking sideways, side steps.
    Sideways,
    /// Crouching, sneaking, creeping, tiptoeing, squatting.
    CrouchSneak,
    /// Going under things, ducking.
    Under,
    /// Balancing, one-leg stances.
    Balance,
    /// Carrying, picking up, putting down, lifting.
    Carry,
    /// Sitting on something.
    Sit,
    /// Climbing, stairs, stepping up.
    Climb,
    /// Crawling.
    Crawl,
    /// Dancing.
    Dance,
}

impl Skill {
    /// Every skill, in report order.
    pub const ALL: [Skill; 13] = [
        Skill::Walk,
        Skill::Turn,
        Skill::Run,
        Skill::JumpHop,
        Skill::Sideways,
        Skill::CrouchSneak,
        Skill::Under,
        Skill::Balance,
        Skill::Carry,
        Skill::Sit,
        Skill::Climb,
        Skill::Crawl,
        Skill::Dance,
    ];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Skill::Walk => "walk",
            Skill::Turn => "turn",
            Skill::Run => "run",
            Skill::JumpHop => "jump/hop",
            Skill::Sideways => "sideways",
            Skill::CrouchSneak => "crouch/sneak",
            Skill::Under => "under",
            Skill::Balance => "balance/one leg",
            Skill::Carry => "carry/pick up",
            Skill::Sit => "sit",
            Skill::Climb => "climb",
            Skill::Crawl => "crawl",
            Skill::Dance => "dance",
        }
    }

    /// Word prefixes of a description that name the skill (matched at the start of a word,
    /// lower case), and phrases matched anywhere.
    fn words(self) -> (&'static [&'static str], &'static [&'static str]) {
        match self {
            Skill::Walk => (&["walk", "stroll", "march", "stride"], &[]),
            Skill::Turn => (&["turn", "veer", "pivot"], &[]),
            Skill::Run => (&["run", "jog", "sprint"], &[]),
            Skill::JumpHop => (&["jump", "hop", "leap"], &[]),
            Skill::Sideways => (&["sideways", "sidestep", "sideway"], &["side step", "side to side"]),
            Skill::CrouchSneak => (&["crouch", "sneak", "creep", "tiptoe", "squat", "stealth"], &["on toes"]),
            Skill::Under => (&["under", "duck", "limbo"], &[]),
            Skill::Balance => (&["balanc", "arabesque"], &["one leg", "one foot", "left foot", "right foot"]),
            Skill::Carry => (&["carry", "pick", "lift", "suitcase", "placing", "putting", "deposit", "grab"], &[]),
            Skill::Sit => (&["sit", "seat", "chair"], &[]),
            Skill::Climb => (&["climb", "ladder", "stair", "stepstool"], &["step up", "step over", "step stool"]),
            Skill::Crawl => (&["crawl"], &[]),
            Skill::Dance => (&["danc", "salsa", "charleston", "waltz", "lindy", "tango"], &[]),
        }
    }

    /// Whether a description names this skill.
    pub fn named_by(self, description: &str) -> bool {
        let lower = description.to_lowercase();
        let (prefixes, phrases) = self.words();
        let words: Vec<&str> = lower.split(|c: char| !c.is_ascii_alphanumeric()).filter(|w| !w.is_empty()).collect();
        // "hop on left foot" is a balance skill only with a hop or stand; "walk on left foot" is not.
        let phrase_hit = phrases.iter().any(|p| lower.contains(p))
            && (self != Skill::Balance
                || words.iter().any(|w| ["hop", "stand", "balanc", "one"].iter().any(|v| w.starts_with(v))));
        phrase_hit || words.iter().any(|w| prefixes.iter().any(|p| w.starts_with(p)))
    }

    /// Every skill a description names.
    pub fn of(description: &str) -> Vec<Skill> {
        Skill::ALL.into_iter().filter(|s| s.named_by(description)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descriptions_name_their_skills() {
        assert_eq!(
            Skill::of("walk sideways and turn (opposite direction)"),
            vec![Skill::Walk, Skill::Turn, Skill::Sideways]
        );
        assert_eq!(Skill::of("Mickey sneaking walk"), vec![Skill::Walk, Skill::CrouchSneak]);
        assert_eq!(Skill::of("Hop on left foot"), vec![Skill::JumpHop, Skill::Balance]);
        assert_eq!(Skill::of("Run Duck Underneath"), vec![Skill::Run, Skill::Under]);
        assert_eq!(Skill::of("balance on one leg, outstretched arms"), vec![Skill::Balance]);
        assert_eq!(Skill::of("pick up box, carry it"), vec![Skill::Carry]);
        assert!(Skill::of("salsa").contains(&Skill::Dance));
        // "understand" is no "under" skill only by accident of prefix; words are matched whole at
        // their start, so "thunder" is not under.
        assert!(!Skill::Under.named_by("thunder clap"));
        assert!(!Skill::Run.named_by("prune the tree"));
    }
}
