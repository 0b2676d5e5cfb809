//! The semantic check of retrieval (RG-DNO supp. A "Semantic Check"): a candidate whose
//! description contradicts the prompt is not scored, however well it fits `C_R`.
//!
//! A candidate is described twice ([`Described`]): by what its motion measurably does (a corpus
//! window's first caption, made only from the tags measured on its joints: the action, the
//! direction of travel relative to facing, the turn; a database sequence's label) and by
//! everything said of it (every caption, with the description of the take it comes from). Direction
//! words and gaits are checked against the measured sentence, since a take's description speaks
//! of the whole take ("walk forward, turn around, walk back") while a window does one part of it;
//! the action verbs of counting tasks against everything said, since a take's description carries
//! verbs the tags cannot measure ("clap", "kick", "punch").

/// Pairs of direction words that contradict each other (either way round).
const DIRECTION_CONTRADICTIONS: [(&str, &str); 3] = [("forward", "backward"), ("left", "right"), ("up", "down")];

/// Pairs of gaits that contradict each other (either way round): a walk always has a foot on
/// the ground, these have a flight phase. A crawl is not among them: the paper retrieves
/// crawling for walking prompts (RG-DNO Fig. 3), to pass under barriers.
const GAIT_CONTRADICTIONS: [(&str, &str); 5] =
    [("walk", "run"), ("walk", "jog"), ("walk", "jump"), ("walk", "hop"), ("walk", "leap")];

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

/// The supplementary's keyword check: `false` when the measured description holds a direction
/// word or a gait that contradicts one of `prompt`'s and that the prompt does not name itself
/// ("backwards" against "walks forwards", "jumps" against "walks", but not "turns right" against
/// "turns left, then right"), or when `counting` and the prompt names an action verb that
/// nothing said of the candidate holds. Words match by stem ("walk" matches "walks" and
/// "walking").
pub fn semantically_consistent(prompt: &str, candidate: Described<'_>, counting: bool) -> bool {
    let prompt_words = words(prompt);
    let measured = words(candidate.measured);
    let has = |ws: &[String], stem: &str| ws.iter().any(|w| w.starts_with(stem));
    let contradicts =
        |named: &str, other: &str| has(&prompt_words, named) && !has(&prompt_words, other) && has(&measured, other);
    if DIRECTION_CONTRADICTIONS.iter().chain(&GAIT_CONTRADICTIONS).any(|&(a, b)| contradicts(a, b) || contradicts(b, a))
    {
        return false;
    }
    if counting {
        let said = words(candidate.said);
        let verbs: Vec<&str> = ACTION_VERBS.iter().copied().filter(|v| has(&prompt_words, v)).collect();
        if !verbs.is_empty() && !verbs.iter().any(|v| has(&said, v)) {
            return false;
        }
    }
    true
}

fn words(text: &str) -> Vec<String> {
    text.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).map(str::to_lowercase).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn consistent(prompt: &str, label: &str, counting: bool) -> bool {
        semantically_consistent(prompt, Described::label(label), counting)
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
    fn directions_and_gaits_are_read_from_the_measured_sentence_and_verbs_from_everything_said() {
        // The take says "walk back", the window measurably walks forward: kept.
        let window = Described {
            measured: "a person walks forward",
            said: "a person walks forward | walk forward, turn around, walk back: someone steps ahead",
        };
        assert!(semantically_consistent("a man walks forwards", window, false));
        // The window runs, whatever the take's description says.
        let running = Described { measured: "a person runs forward", said: "walk: a person runs forward" };
        assert!(!semantically_consistent("a man walks forwards", running, false));
        // A clap is in the take's description only.
        let clapping = Described { measured: "a person stands", said: "a person stands | clapping hands" };
        assert!(semantically_consistent("a person claps three times", clapping, true));
        assert!(!semantically_consistent("a person kicks three times", clapping, true));
    }
}
