//! Captions that say what a window does: a sentence built from the window's measured
//! [`MotionTags`] (the action, the direction of travel relative to facing, the turn, speed and
//! hand states), in several phrasings so a model does not learn one template, each of them bare
//! and two of them also with the take's description beside it (what CMU says of the whole
//! take: vocabulary the tags cannot give, such as "salsa" or "basketball dribble"). The bare
//! sentences are what a user's prompt looks like, so most of a window's captions are bare.
//!
//! Rules, in order: head under 0.6 m for a quarter of the window → crawls (moving) or is on the
//! floor; sitting → sits; airborne with one foot up → hops on one foot; airborne and faster
//! than 2 m/s → runs; airborne → jumps; one foot up for 1.5 s and slower than 0.4 m/s →
//! balances on one leg; faster than 2 m/s → runs; faster than 0.25 m/s → walks (crouched:
//! sneaks); otherwise stands (crouched: crouches).

use super::tags::{MotionTags, TravelDirection};

/// Phrasings made per window.
pub const PHRASINGS: usize = 3;

/// What the body does, the first rule that matches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Moving with the head near the floor.
    Crawl,
    /// Down on the floor, not moving.
    OnFloor,
    /// Seated.
    Sit,
    /// Airborne on one foot.
    HopOneFoot,
    /// Airborne, fast.
    Run,
    /// Airborne, not fast.
    Jump,
    /// One foot up, in place.
    Balance,
    /// Crouched and moving.
    Sneak,
    /// Moving.
    Walk,
    /// Crouched in place.
    Crouch,
    /// In place.
    Stand,
}

impl Action {
    /// The action of a window's tags.
    pub fn of(tags: &MotionTags) -> Self {
        let v = tags.speed_m_per_s;
        if tags.on_floor {
            return if v > 0.15 { Action::Crawl } else { Action::OnFloor };
        }
        if tags.sitting {
            Action::Sit
        } else if tags.airborne() && tags.one_foot() {
            Action::HopOneFoot
        } else if tags.airborne() && v > 2.0 {
            Action::Run
        } else if tags.airborne() {
            Action::Jump
        } else if tags.one_foot() && v < 0.4 {
            Action::Balance
        } else if v > 2.0 {
            Action::Run
        } else if v > 0.25 {
            if tags.crouched {
                Action::Sneak
            } else {
                Action::Walk
            }
        } else if tags.crouched {
            Action::Crouch
        } else {
            Action::Stand
        }
    }

    /// The verb phrase of the first phrasing, the one a window's displayed caption uses
    /// ("crawls", "hops on one foot").
    pub fn verb(self) -> &'static str {
        self.verbs()[0]
    }

    /// Verb phrases, one per phrasing.
    fn verbs(self) -> [&'static str; PHRASINGS] {
        match self {
            Action::Crawl => ["crawls", "moves on all fours", "crawls on hands and knees"],
            Action::OnFloor => ["lies on the floor", "is down on the ground", "stays low on the floor"],
            Action::Sit => ["sits", "is seated", "sits down on something"],
            Action::HopOneFoot => ["hops on one foot", "hops on one leg", "jumps along on one foot"],
            Action::Run => ["runs", "jogs", "runs quickly"],
            Action::Jump => ["jumps", "leaps", "jumps up"],
            Action::Balance => ["balances on one leg", "stands on one foot", "holds a one-legged stance"],
            Action::Sneak => ["sneaks in a crouch", "creeps low", "walks crouched"],
            Action::Walk => ["walks", "steps", "strolls"],
            Action::Crouch => ["crouches", "squats down", "stays low in a crouch"],
            Action::Stand => ["stands", "stands in place", "stays where they are"],
        }
    }

    /// Whether the action travels, so a direction of travel belongs to it.
    fn travels(self) -> bool {
        matches!(self, Action::Crawl | Action::HopOneFoot | Action::Run | Action::Jump | Action::Sneak | Action::Walk)
    }
}

fn direction_words(direction: TravelDirection) -> [&'static str; PHRASINGS] {
    match direction {
        TravelDirection::Forwards => ["forward", "ahead", "forwards"],
        TravelDirection::Backwards => ["backwards", "backward", "in reverse"],
        TravelDirection::SidewaysLeft => ["sideways to the left", "sideways to their left", "to the left, sideways"],
        TravelDirection::SidewaysRight => {
            ["sideways to the right", "sideways to their right", "to the right, sideways"]
        }
    }
}

const SUBJECTS: [&str; PHRASINGS] = ["a person", "someone", "the person"];

/// The sentence of phrasing `k` (0..[`PHRASINGS`]) for a window's tags, without the take's
/// description: "a person walks slowly forward and turns left by about 90 degrees".
pub fn sentence(tags: &MotionTags, k: usize) -> String {
    let k = k % PHRASINGS;
    mixed_sentence(tags, k, k, k)
}

/// The sentence with the verb (and the turn and hand clauses) of phrasing `k`, the subject of
/// phrasing `subject` and the direction words of phrasing `direction` (each 0..[`PHRASINGS`]),
/// so that across windows every verb meets every subject and direction word.
fn mixed_sentence(tags: &MotionTags, k: usize, subject: usize, direction: usize) -> String {
    let action = Action::of(tags);
    let mut words = vec![SUBJECTS[subject].to_owned(), action.verbs()[k].to_owned()];
    if action == Action::Walk {
        if tags.speed_m_per_s < 0.7 {
            words.push("slowly".into());
        } else if tags.speed_m_per_s > 1.7 {
            words.push("briskly".into());
        }
    }
    if action.travels() {
        if let Some(d) = tags.direction {
            words.push(direction_words(d)[direction].into());
        }
    }
    let mut s = words.join(" ");
    if let Some(left) = tags.turn_left() {
        let side = if left { "left" } else { "right" };
        let degrees = (tags.turn_deg.abs() / 45.0).round() as i64 * 45;
        s += &match k {
            0 if degrees >= 90 => format!(" and turns {side} by about {degrees} degrees"),
            1 => format!(", turning to the {side}"),
            _ => format!(" and turns {side}"),
        };
    }
    if tags.hands_above_head() {
        s += [" with the hands raised above the head", ", raising both hands", " with the arms up over the head"][k];
    }
    if tags.hands_together() {
        s += [" with the hands together", ", holding the hands together", " with the hands joined"][k];
    }
    s
}

/// Misspellings and side words that name no side in CMU's file-name descriptions, mended before
/// they are split into words (`UpRightSequence` is upright and `RightAngleTurns` are 90-degree
/// turns, neither a right to mirror).
const WORDING: [(&str, &str); 7] = [
    ("UpRight", "Upright"),
    ("RightAngleTurns", "NinetyDegreeTurns"),
    ("Sraight", "Straight"),
    ("Tigher", "Tighter"),
    ("Bannana", "Banana"),
    ("Sequnce", "Sequence"),
    ("Painfulleftknee", "PainfulLeftKnee"),
];

/// A take's description as words that a sentence encoder reads and that mirroring can mirror
/// (`database::mirror_label` swaps whole words "left" and "right"). About 250 CMU takes are
/// described by a file name instead: `Reach_Left002`, `RunningWideLeft CleanedGRS`. Those are
/// split into lower-case words at underscores, capitals and digits, their take numbering
/// (`001`, `_01`) and the cleaning note (`CleanedGRS`, `Cleaned GRS`) dropped: `reach left`,
/// `running wide left`. A description that is only a file name (`106_15.amc`) or a number
/// (`180`) says nothing and becomes empty. Descriptions in words (`walk, stop, sit down`,
/// `Walk Left`) come back as they are.
pub fn readable_description(raw: &str) -> String {
    let raw = raw.trim();
    if raw.to_ascii_lowercase().ends_with(".amc")
        || raw.chars().all(|c| c.is_ascii_digit() || c.is_whitespace() || c == '_')
    {
        return String::new();
    }
    let mended = WORDING.iter().fold(raw.to_owned(), |s, (wrong, right)| s.replace(wrong, right));
    let tokens: Vec<&str> = mended.split_whitespace().collect();
    if !tokens.iter().any(|t| t.contains('_') || split_camel_case(t).len() > 1) {
        return raw.to_owned();
    }
    let mut words = Vec::new();
    let mut k = 0;
    while k < tokens.len() {
        let token = tokens[k];
        k += 1;
        if token.eq_ignore_ascii_case("cleanedgrs") {
            continue;
        }
        if token.eq_ignore_ascii_case("cleaned") && tokens.get(k).is_some_and(|t| t.eq_ignore_ascii_case("grs")) {
            k += 1;
            continue;
        }
        for piece in token.split('_') {
            let numbered = piece.trim_end_matches(|c: char| c.is_ascii_digit());
            let digits = &piece[numbered.len()..];
            let piece = if digits.starts_with('0') { numbered } else { piece };
            words.extend(split_camel_case(piece).into_iter().map(|w| w.to_ascii_lowercase()));
        }
    }
    words.join(" ")
}

/// Splits a word at a capital after a lower-case letter, a digit after a letter and a capital
/// after a digit: `RunningWideLeft` → `Running Wide Left`, `90TwistsFall` → `90 Twists Fall`.
pub(crate) fn split_camel_case(word: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut previous: Option<char> = None;
    for c in word.chars() {
        let boundary = previous.is_some_and(|p| {
            (p.is_ascii_lowercase() && c.is_ascii_uppercase())
                || (p.is_ascii_alphabetic() && c.is_ascii_digit())
                || (p.is_ascii_digit() && c.is_ascii_uppercase())
        });
        match out.last_mut() {
            Some(last) if !boundary => last.push(c),
            _ => out.push(c.to_string()),
        }
        previous = Some(c);
    }
    out
}

/// Every caption of the window numbered `window` (any number that differs between
/// neighbouring windows, such as its index in the corpus): the [`PHRASINGS`] bare sentences,
/// the first one phrasing 0 exactly ("a person walks forward", what displays and retrieval
/// show), the others with their subject and direction words rotated by `window` (over nine
/// consecutive windows each verb meets every subject and direction word); then, when the take
/// has a description, the second and third sentence again beside it, in two forms.
pub fn captions(tags: &MotionTags, description: &str, window: usize) -> Vec<String> {
    let description = description.trim();
    let bare: Vec<String> = (0..PHRASINGS)
        .map(|k| match k {
            0 => sentence(tags, 0),
            _ => mixed_sentence(tags, k, (k + window) % PHRASINGS, (k + window / PHRASINGS) % PHRASINGS),
        })
        .collect();
    let described = (!description.is_empty())
        .then(|| [format!("{}: {}", description, bare[1]), format!("{} (a take of: {})", bare[2], description)]);
    bare.iter().cloned().chain(described.into_iter().flatten()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tags() -> MotionTags {
        MotionTags {
            speed_m_per_s: 1.2,
            travel_m: 6.0,
            direction: Some(TravelDirection::Forwards),
            turn_deg: 0.0,
            crouched: false,
            sitting: false,
            on_floor: false,
            airborne_frames: 0,
            one_foot_up_s: 0.0,
            hands_above_head_frames: 0,
            hands_together_frames: 0,
        }
    }

    #[test]
    fn captions_say_what_the_tags_measure() {
        assert_eq!(sentence(&tags(), 0), "a person walks forward");
        let t = MotionTags { direction: Some(TravelDirection::SidewaysRight), speed_m_per_s: 0.5, ..tags() };
        assert_eq!(sentence(&t, 0), "a person walks slowly sideways to the right");
        let t = MotionTags { crouched: true, turn_deg: 95.0, ..tags() };
        assert_eq!(sentence(&t, 0), "a person sneaks in a crouch forward and turns left by about 90 degrees");
        assert_eq!(sentence(&t, 1), "someone creeps low ahead, turning to the left");
        let t = MotionTags { airborne_frames: 6, one_foot_up_s: 2.0, speed_m_per_s: 0.8, ..tags() };
        assert_eq!(Action::of(&t), Action::HopOneFoot);
        let t = MotionTags { one_foot_up_s: 2.0, speed_m_per_s: 0.1, direction: None, ..tags() };
        assert_eq!(sentence(&t, 0), "a person balances on one leg");
        let t = MotionTags { hands_above_head_frames: 30, speed_m_per_s: 0.0, direction: None, ..tags() };
        assert_eq!(sentence(&t, 0), "a person stands with the hands raised above the head");
    }

    #[test]
    fn file_name_descriptions_become_words_and_word_descriptions_stay() {
        for (raw, readable) in [
            ("Reach_Left002", "reach left"),
            ("RunningWideLeft CleanedGRS", "running wide left"),
            ("LeftDrive (right then left) Cleaned GRS", "left drive (right then left)"),
            ("SraightDriveFromStop", "straight drive from stop"),
            ("UpRightSequence", "upright sequence"),
            ("SlowWalkRightAngleTurns", "slow walk ninety degree turns"),
            ("Painfulleftknee", "painful left knee"),
            ("charleston_01", "charleston"),
            ("Figure8s001", "figure 8s"),
            ("90TwistsFall", "90 twists fall"),
            ("360 smallStumble", "360 small stumble"),
            ("Sun Salutation001", "sun salutation"),
            ("106_15.amc", ""),
            (" 180 ", ""),
            ("walk, stop, sit down", "walk, stop, sit down"),
            ("Walk Left", "Walk Left"),
            ("hop turn left 180 degrees in air", "hop turn left 180 degrees in air"),
        ] {
            assert_eq!(readable_description(raw), readable, "{raw}");
            assert_eq!(readable_description(readable), readable, "{raw}: not idempotent");
        }
    }

    #[test]
    fn every_phrasing_is_bare_and_the_words_rotate_across_windows() {
        let all = captions(&tags(), "walk, stop, sit down", 0);
        assert_eq!(
            all,
            [
                "a person walks forward",
                "someone steps ahead",
                "the person strolls forwards",
                "walk, stop, sit down: someone steps ahead",
                "the person strolls forwards (a take of: walk, stop, sit down)"
            ]
        );
        assert_eq!(captions(&tags(), " ", 0), all[..PHRASINGS]);
        // The next windows give the same verbs other subjects, then other direction words;
        // the first caption stays phrasing 0.
        assert_eq!(
            captions(&tags(), "", 1),
            ["a person walks forward", "the person steps ahead", "a person strolls forwards"]
        );
        assert_eq!(captions(&tags(), "", 3)[1..], ["someone steps forwards", "the person strolls forward"]);
        let strolls: std::collections::BTreeSet<String> = (0..9).map(|w| captions(&tags(), "", w)[2].clone()).collect();
        assert_eq!(strolls.len(), 9, "{strolls:?}");
    }
}
