//! The semantic check of retrieval (RG-DNO supp. A "Semantic Check"): a candidate whose
//! description contradicts the prompt is not scored, however well it fits `C_R`.
//!
//! A candidate is described twice ([`Described`]): by what its motion measurably does (a corpus
//! window's first caption, made only from the tags measured on its joints: the action, the
//! direction of travel relative to facing, the turn; a database sequence's label) and by
//! everything said of it (every caption, with the description of the take it comes from).
//! Direction words and actions are checked against the measured sentence, since a take's
//! description speaks of the whole take ("walk forward, turn around, walk back") while a window
//! does one part of it; the action verbs of counting tasks against everything said, since a
//! take's description carries verbs the tags cannot measure ("clap", "kick", "punch").
//!
//! **Actions.** The prompt's words name actions of [`Action`], the vocabulary of the measured
//! captions (a crawl, a jump, a sit, a walk, …; [`named_actions`]). When it names any, a
//! candidate whose measured sentence names only other actions is dropped, unless one of the
//! prompt's actions [`accepts`] it as a stand-in: a walk may be a crawl or a crouched sneak
//! (the paper retrieves crawling for walking prompts, RG-DNO Fig. 3, to pass under barriers),
//! but never a jump, a run or a stand; a crawl is never a jump.
//!
//! **The skill.** Beyond dropping contradictions, a prompt that names skills other than
//! walking ([`Heard::skills`]: a crawl, a sit, a hop, a jump, a run, a side-step, a crouch or a
//! duck, a balance, a carry) is heard as asking for them: retrieval scores only the windows that
//! do one of them by measurement ([`crate::corpus::family::Family::happens_in`]) when there are any.
//! Walks and turns are left to `C_R`: they are most of the corpus, and a walking task may take
//! a crawl or a sneak as its stand-in under a barrier (RG-DNO Fig. 3).

use crate::corpus::caption::Action;
use crate::corpus::family::Family;

/// Pairs of direction words that contradict each other (either way round).
const DIRECTION_CONTRADICTIONS: [(&str, &str); 3] = [("forward", "backward"), ("left", "right"), ("up", "down")];

/// Word stems that name each action, in prompts and in the measured captions (whose verbs,
/// [`crate::corpus::caption`]'s first phrasing, are among them: "crawls", "lies on the floor",
/// "sits", "hops on one foot", "runs", "jumps", "balances on one leg", "sneaks in a crouch",
/// "walks", "crouches", "stands").
const ACTION_STEMS: [(&str, Action); 27] = [
    ("crawl", Action::Crawl),
    ("fours", Action::Crawl),
    ("lie", Action::OnFloor),
    ("lying", Action::OnFloor),
    ("prone", Action::OnFloor),
    ("sit", Action::Sit),
    ("seat", Action::Sit),
    ("hop", Action::HopOneFoot),
    ("run", Action::Run),
    ("jog", Action::Run),
    ("sprint", Action::Run),
    ("jump", Action::Jump),
    ("leap", Action::Jump),
    ("balanc", Action::Balance),
    ("sneak", Action::Sneak),
    ("creep", Action::Sneak),
    ("tiptoe", Action::Sneak),
    ("walk", Action::Walk),
    ("stroll", Action::Walk),
    ("step", Action::Walk),
    ("march", Action::Walk),
    ("wander", Action::Walk),
    ("stumbl", Action::Walk),
    ("crouch", Action::Crouch),
    ("squat", Action::Crouch),
    ("duck", Action::Crouch),
    ("stand", Action::Stand),
];

/// The actions `text` names, in the order of `ACTION_STEMS`, each once.
pub fn named_actions(text: &str) -> Vec<Action> {
    actions_in(&words(text))
}

/// [`named_actions`] of a text's lower-case `words`.
fn actions_in(words: &[String]) -> Vec<Action> {
    let mut named: Vec<Action> = Vec::new();
    for (stem, action) in ACTION_STEMS {
        if words.iter().any(|w| w.starts_with(stem)) && !named.contains(&action) {
            named.push(action);
        }
    }
    named
}

/// What a report says of the prompt's actions that no window of the database does
/// ([`crate::generation::rgdno::retrieval::RetrievalOutcome::missing_actions`]), given by
/// their verbs ([`Action::verb`]): "no window of the database crawls or sits"; `None` when there
/// are none.
pub fn missing_actions_note<'a>(verbs: impl IntoIterator<Item = &'a str>) -> Option<String> {
    let verbs: Vec<&str> = verbs.into_iter().collect();
    (!verbs.is_empty()).then(|| format!("no window of the database {}", verbs.join(" or ")))
}

/// Whether a prompt that names `named` accepts a window measured doing `measured`: the same
/// action, or a stand-in that does the prompt's work (a walk may crawl or sneak under a
/// barrier; a jump may be a hop or a running leap; a sit or a stand passes through the poses
/// around it).
pub fn accepts(named: Action, measured: Action) -> bool {
    use Action::*;
    let stand_ins: &[Action] = match named {
        Walk => &[Crawl, Sneak],
        Run => &[Jump],
        Jump => &[HopOneFoot, Run],
        HopOneFoot => &[Balance],
        Crawl => &[OnFloor],
        OnFloor => &[Crawl, Sit, Crouch],
        Sit => &[Stand, Crouch, Walk],
        Balance => &[Stand, HopOneFoot],
        Sneak => &[Walk, Crouch, Crawl],
        Crouch => &[Sneak, Stand, Walk, Crawl],
        Stand => &[Balance, Crouch],
    };
    named == measured || stand_ins.contains(&measured)
}

/// Word stems by which a prompt asks for a turn.
const TURN_STEMS: [&str; 7] = ["turn", "around", "spin", "rotat", "circl", "twirl", "pivot"];

/// The smallest turn, in degrees, of a window that does a skill the prompt asks for but that
/// retrieval passes over when the prompt names no turn ([`Heard::turns_unasked`]): half round
/// to the nearest 45°, as the measured captions state turns ("by about 180 degrees").
pub const UNASKED_TURN_DEG: f64 = 157.5;

/// Action verbs the semantic check of a counting task looks for, by stem.
const ACTION_VERBS: [&str; 12] =
    ["walk", "run", "jog", "jump", "hop", "crawl", "clap", "kick", "punch", "wave", "step", "touch"];

/// What the semantic check reads of a candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Described<'a> {
    /// What the motion measurably does: a corpus window's caption made from its measured tags
    /// ("a person walks forward and turns left"), or a database sequence's label.
    pub measured: &'a str,
    /// Everything said of it: every caption of the window with its take's description, or the
    /// label.
    pub said: &'a str,
}

impl<'a> Described<'a> {
    /// A candidate known only by one label (a database sequence).
    pub fn label(label: &'a str) -> Self {
        Described { measured: label, said: label }
    }
}

/// A prompt as the semantic check hears it, read once per query: its words, the actions they
/// name, and whether the task counts actions.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Heard {
    words: Vec<String>,
    actions: Vec<Action>,
    skills: Vec<Family>,
    counting: bool,
}

impl Heard {
    /// `prompt` heard for a task that counts actions (`counting`) or not.
    pub fn new(prompt: &str, counting: bool) -> Self {
        let words = words(prompt);
        let mut skills = Family::all_named_in(prompt);
        skills.retain(|f| !f.is_walking());
        Heard { actions: actions_in(&words), words, skills, counting }
    }

    /// The skills the prompt asks for, which retrieval looks for first, the most specific
    /// first: the families it names ([`Family::all_named_in`]) other than walking
    /// ([`Family::is_walking`]).
    pub fn skills(&self) -> &[Family] {
        &self.skills
    }

    /// The actions the prompt names ([`named_actions`]).
    pub fn actions(&self) -> &[Action] {
        &self.actions
    }

    /// Whether a candidate that turns `turn_deg` degrees (either way, as measured) turns half
    /// round or more ([`UNASKED_TURN_DEG`]) while the prompt asks for no turn: a take that
    /// wheels ("jumps forward and turns left by about 225 degrees") does a skill, but not the one
    /// "jumps forward" asks for. Retrieval passes over such takes only among those that do the
    /// prompt's skill ([`Self::skills`]); walks keep the paper's ranking, whose crops of long
    /// takes turn.
    pub fn turns_unasked(&self, turn_deg: f64) -> bool {
        let asked = TURN_STEMS.iter().any(|t| self.words.iter().any(|w| w.starts_with(t)));
        !asked && turn_deg.abs() >= UNASKED_TURN_DEG
    }

    /// The supplementary's keyword check: `false` when the measured description holds a
    /// direction word that contradicts one of the prompt's and that the prompt does not name
    /// itself ("backwards" against "walks forwards", but not "turns right" against "turns left,
    /// then right"), when the prompt names actions and the measured description names only
    /// actions that none of them [`accepts`] ("jumps" against "crawls", "stands" against
    /// "walks"), or when the task counts and the prompt names an action verb that nothing said
    /// of the candidate holds. Words match by stem ("walk" matches "walks" and "walking").
    pub fn consistent(&self, candidate: Described<'_>) -> bool {
        let measured = words(candidate.measured);
        let has = |ws: &[String], stem: &str| ws.iter().any(|w| w.starts_with(stem));
        let contradicts =
            |named: &str, other: &str| has(&self.words, named) && !has(&self.words, other) && has(&measured, other);
        if DIRECTION_CONTRADICTIONS.iter().any(|&(a, b)| contradicts(a, b) || contradicts(b, a)) {
            return false;
        }
        let done = actions_in(&measured);
        if !self.actions.is_empty()
            && !done.is_empty()
            && !done.iter().any(|&d| self.actions.iter().any(|&a| accepts(a, d)))
        {
            return false;
        }
        if self.counting {
            let said = words(candidate.said);
            let verbs: Vec<&str> = ACTION_VERBS.iter().copied().filter(|v| has(&self.words, v)).collect();
            if !verbs.is_empty() && !verbs.iter().any(|v| has(&said, v)) {
                return false;
            }
        }
        true
    }
}

fn words(text: &str) -> Vec<String> {
    text.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).map(str::to_lowercase).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn consistent(prompt: &str, label: &str, counting: bool) -> bool {
        Heard::new(prompt, counting).consistent(Described::label(label))
    }

    #[test]
    fn the_semantic_check_drops_contradicting_directions_gaits_and_missing_verbs() {
        assert!(!consistent("a man walks forwards", "a person walks backwards", false));
        assert!(consistent("a man walks forwards", "a person walks forward", false));
        assert!(consistent("a man walks forwards", "a person crawls forward on the ground", false));
        assert!(!consistent("a person walks and turns left", "a person walks and turns right", false));
        // A direction the prompt names both ways contradicts nothing.
        assert!(consistent("a person turns left, then right", "a person walks and turns right", false));
        // Gaits: a walk is not a jump or a run (either way round), but may be a crawl.
        assert!(!consistent("a man walks forwards", "a person jumps forward", false));
        assert!(!consistent("a man walks forwards", "a person runs forward", false));
        assert!(!consistent("a person jumps forward", "a person walks forward", false));
        assert!(consistent("a man runs forwards and jumps over an obstacle", "a person jumps forward", false));
        assert!(consistent("a man walks forwards and jumps", "a person jumps forward", false));
        // Counting tasks need the action verb.
        assert!(!consistent("a man walks six steps", "a person dances in place", true));
        assert!(consistent("a man walks six steps", "a person walks forward punching", true));
        assert!(consistent("a man walks six steps", "a person dances in place", false));
    }

    #[test]
    fn a_window_whose_measured_action_the_prompt_does_not_accept_is_dropped() {
        // The crawl under a table retrieved a jump-turn; a wall walk retrieved a stand.
        assert!(!consistent("a person crawls forward under a table", "a person jumps forward and turns right", false));
        assert!(consistent("a person crawls forward under a table", "a person crawls forward", false));
        assert!(!consistent("walk forwards 4 m with the right hand on a wall", "a person stands", false));
        // A walk may crawl or sneak under a barrier, but not lie still on the floor.
        assert!(consistent("a man walks forwards", "a person sneaks in a crouch forward", false));
        assert!(!consistent("a man walks forwards", "a person lies on the floor", false));
        // A sit passes through standing; a one-foot hop is not a two-foot jump.
        assert!(consistent("a person sits down on a chair", "a person stands", false));
        assert!(!consistent("a person hops on one foot across a line", "a person jumps forward", false));
        // A prompt that names no action, or a label that names none, checks nothing.
        assert!(consistent("a person reaches up high with a hand", "a person jumps forward", false));
        assert!(consistent("a person crawls", "a salsa dance", false));
    }

    #[test]
    fn every_measured_caption_verb_names_its_own_action() {
        use Action::*;
        let all = [Crawl, OnFloor, Sit, HopOneFoot, Run, Jump, Balance, Sneak, Walk, Crouch, Stand];
        for action in all {
            let named = named_actions(&format!("a person {} forward", action.verb()));
            assert!(named.contains(&action), "{action:?}: {named:?}");
            assert!(named.iter().all(|&n| accepts(action, n)), "{action:?} must accept every action its verb names");
        }
        assert_eq!(named_actions("a man runs forwards and jumps over an obstacle"), [Run, Jump]);
        assert_eq!(named_actions("a person is crawling on all fours"), [Crawl]);
        assert!(named_actions("a person reaches up high with a hand again and again").is_empty());
        assert_eq!(
            missing_actions_note([Crawl.verb(), Sit.verb()]).unwrap(),
            "no window of the database crawls or sits"
        );
        assert_eq!(missing_actions_note([]), None);
    }

    #[test]
    fn the_skills_sought_are_the_named_families_other_than_walks_and_turns() {
        let skills = |prompt: &str| Heard::new(prompt, false).skills().to_vec();
        assert_eq!(skills("a person walks to a chair and sits down"), [Family::SitDown]);
        assert_eq!(skills("a person jumps forward onto a step"), [Family::Jump]);
        assert_eq!(skills("a man runs forwards and jumps over an obstacle"), [Family::Jump, Family::Run]);
        assert_eq!(skills("a person ducks under a barrier while walking forward"), [Family::Sneak]);
        assert_eq!(skills("a person carries a box forward"), [Family::Carry]);
        assert!(skills("a man walks forwards").is_empty());
        assert!(skills("a person walks and turns left").is_empty());
        assert!(skills("a person reaches up high with a hand again and again").is_empty());
    }

    #[test]
    fn half_a_turn_that_the_prompt_does_not_ask_for_is_unasked() {
        // "jumps forward and turns left by about 225 degrees", "… 135 degrees", no turn.
        let (wheel, quarter) = (225.0, 135.0);
        assert!(Heard::new("a person jumps forward onto a step", false).turns_unasked(wheel));
        assert!(!Heard::new("a person jumps forward and turns around", false).turns_unasked(wheel));
        assert!(!Heard::new("a person jumps forward", false).turns_unasked(quarter));
        assert!(!Heard::new("a person jumps forward", false).turns_unasked(0.0));
    }

    #[test]
    fn directions_and_gaits_are_read_from_the_measured_sentence_and_verbs_from_everything_said() {
        // The take says "walk back", the window measurably walks forward: kept.
        let window = Described {
            measured: "a person walks forward",
            said: "a person walks forward | walk forward, turn around, walk back: someone steps ahead",
        };
        assert!(Heard::new("a man walks forwards", false).consistent(window));
        // The window runs, whatever the take's description says.
        let running = Described { measured: "a person runs forward", said: "walk: a person runs forward" };
        assert!(!Heard::new("a man walks forwards", false).consistent(running));
        // A clap is in the take's description only.
        let clapping = Described { measured: "a person stands", said: "a person stands | clapping hands" };
        assert!(Heard::new("a person claps three times", true).consistent(clapping));
        assert!(!Heard::new("a person kicks three times", true).consistent(clapping));
    }
}
