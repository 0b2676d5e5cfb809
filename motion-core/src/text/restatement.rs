//! Restating a free prompt in its prior's caption words: a verb that no training caption uses
//! ("ambles", "veers") becomes the nearest verb the captions do use, found through WordNet's
//! synonyms and hypernyms ("walks", "turns").
//!
//! Why: the sentence encoder ranks such verbs by their company, not their meaning.
//! "someone ambles and veers off to their left" lies nearer "a person stays where they are (a
//! take of: Reach_Left002)" (cosine 0.59) than any walking-and-turning caption, so the caption
//! bank ([`super::caption_bank`]) without the restatement hears a reach and the prior's samples
//! turn left in 6 % (`fixtures/model/MODEL_CARD.md`, "By prompt"). WordNet says an amble is a
//! walk and a veer a turn.
//!
//! The rule, word by word (maximal runs of ASCII letters; everything else is kept as it is):
//! 1. a word some caption uses, or one WordNet does not know as a verb, is kept;
//! 2. so is one whose lemma a caption uses ("paces": "pace"), or a light verb
//!    ([`LIGHT_VERBS`]: "keeps" is not a posture), or one WordNet's tagged texts read more often
//!    as a noun, an adjective or an adverb ("distance", "long strides", "at full speed") unless
//!    it is a third-person verb right after a word read as a noun, its subject ("a woman
//!    strides", "someone springs");
//! 3. otherwise each of its lemmas' first sense of bodily motion ([`crate::text::wordnet::BODILY_MOTION`])
//!    is searched breadth first: the sense's own words, its hypernyms, theirs (at most
//!    [`HYPERNYM_LEVELS`] up). The first word found that is a caption verb (a caption
//!    word WordNet knows as a verb lemma, not a light one: "turn" must itself be a caption word,
//!    "turns" is not enough) in its own first sense (the synset found is the word's most common
//!    one, so that the sentence encoder reads it as WordNet meant it: "gallop" reaches {ride,
//!    sit} and "strut" {swagger, strut, cock}, but neither is the first sense of "sit" or
//!    "cock") replaces the word, inflected as the word was ("ambles" → "walks", "veering" →
//!    "turning", "sprinted" → "ran"), in the captions' own spelling where they have it.
//!
//! What each condition prevents: without the caption verb's own first sense, "gallop" → "sit",
//! "strut" → "cock", "roam" → "roll" and "twist" → "wrestle"; without the first sense of bodily
//! motion, "landing" → "carrying" (a later sense of "land", bring ashore); without the subject
//! condition "strides" and "springs" are kept as nouns; without the adjective and adverb
//! condition "at full speed" → "at strike rush". Irregular pasts are spelt from WordNet
//! ("bent", not "bended"). Which paraphrases each condition was written on, which held-out
//! paraphrases (`fixtures/model/held_out_paraphrases.tsv`) were written before it, and what it
//! changed on them are in `fixtures/model/MODEL_CARD.md` ("Held-out paraphrases") and
//! `fixtures/model/training/README.md`.

use std::collections::{HashSet, VecDeque};
use std::sync::Arc;

use super::wordnet::{PartOfSpeech, WordNet, BODILY_MOTION};

/// Verbs too general to say what a body does: never a replacement, and a word that may be
/// one of them is kept.
pub const LIGHT_VERBS: [&str; 23] = [
    "be", "have", "do", "make", "go", "get", "take", "come", "move", "travel", "change", "put", "give", "set", "let",
    "keep", "cause", "act", "use", "begin", "start", "stop", "locomote",
];

/// Hypernym levels searched above a sense (0 would be its synonyms only): "ambles" reaches
/// "walk" at 1.
pub const HYPERNYM_LEVELS: usize = 2;

/// A prompt as restated, and the words replaced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Restated {
    /// The restated prompt (the prompt itself when nothing was replaced).
    pub text: String,
    /// Each replaced word and its replacement, in prompt order.
    pub replaced: Vec<(String, String)>,
}

impl Restated {
    /// `prompt` with nothing replaced.
    pub fn unchanged(prompt: &str) -> Self {
        Self { text: prompt.to_owned(), replaced: Vec::new() }
    }
}

/// Restates prompts in the words of one set of captions ([module doc](self)).
#[derive(Debug, Clone)]
pub struct Restatement {
    wordnet: Arc<WordNet>,
    /// Every caption word, lower case.
    known: HashSet<String>,
    /// The caption words WordNet knows as verbs, light verbs left out.
    verbs: HashSet<String>,
}

/// The maximal runs of ASCII letters of `text` and what lies between them, in order; `true`
/// marks a word.
fn tokens(text: &str) -> impl Iterator<Item = (bool, &str)> {
    let mut rest = text;
    std::iter::from_fn(move || {
        let first = rest.chars().next()?;
        let word = first.is_ascii_alphabetic();
        let end = rest.find(|c: char| c.is_ascii_alphabetic() != word).unwrap_or(rest.len());
        let (token, tail) = rest.split_at(end);
        rest = tail;
        Some((word, token))
    })
}

/// How a word is inflected from its lemma.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Form {
    Base,
    ThirdPerson,
    Gerund,
    Past,
}

impl Form {
    fn of(word: &str, lemma: &str) -> Self {
        if word == lemma {
            Form::Base
        } else if word.ends_with("ing") {
            Form::Gerund
        } else if word.ends_with('s') {
            Form::ThirdPerson
        } else {
            Form::Past
        }
    }

    /// `verb` in this form by the regular rules; the first spelling is the usual one.
    fn spellings(self, verb: &str) -> Vec<String> {
        let consonant_y = verb.ends_with('y') && !verb[..verb.len() - 1].ends_with(['a', 'e', 'i', 'o', 'u']);
        let stem = |n: usize| &verb[..verb.len() - n];
        let doubled = format!("{verb}{}", verb.chars().last().unwrap_or_default());
        match self {
            Form::Base => vec![verb.to_owned()],
            Form::ThirdPerson if consonant_y => vec![format!("{}ies", stem(1))],
            Form::ThirdPerson if verb.ends_with(['s', 'x', 'z']) || verb.ends_with("ch") || verb.ends_with("sh") => {
                vec![format!("{verb}es")]
            }
            Form::ThirdPerson => vec![format!("{verb}s"), format!("{verb}es")],
            Form::Gerund if verb.ends_with('e') && !verb.ends_with("ee") => vec![format!("{}ing", stem(1))],
            Form::Gerund => vec![format!("{verb}ing"), format!("{doubled}ing")],
            Form::Past if consonant_y => vec![format!("{}ied", stem(1))],
            Form::Past if verb.ends_with('e') => vec![format!("{verb}d")],
            Form::Past => vec![format!("{verb}ed"), format!("{doubled}ed")],
        }
    }
}

impl Restatement {
    /// A restatement into the words of `captions`.
    pub fn new(wordnet: Arc<WordNet>, captions: &[String]) -> Self {
        let known: HashSet<String> = captions
            .iter()
            .flat_map(|c| tokens(c).filter(|(word, _)| *word).map(|(_, w)| w.to_ascii_lowercase()))
            .collect();
        let verbs = known
            .iter()
            .filter(|w| !LIGHT_VERBS.contains(&w.as_str()) && !wordnet.verb_senses(w).is_empty())
            .cloned()
            .collect();
        Self { wordnet, known, verbs }
    }

    /// `prompt` restated ([module doc](self)).
    pub fn restate(&self, prompt: &str) -> Restated {
        let mut text = String::with_capacity(prompt.len());
        let mut replaced = Vec::new();
        let mut after_noun = false;
        for (is_word, token) in tokens(prompt) {
            let word = token.to_ascii_lowercase();
            let replacement = is_word.then(|| self.replacement(&word, after_noun)).flatten();
            if is_word {
                after_noun = self.reads_as_noun(&word);
            } else if !token.chars().all(char::is_whitespace) {
                after_noun = false;
            }
            match replacement {
                Some(by) => {
                    let by = match token.chars().next() {
                        Some(c) if c.is_ascii_uppercase() => by[..1].to_ascii_uppercase() + &by[1..],
                        _ => by,
                    };
                    text.push_str(&by);
                    replaced.push((token.to_owned(), by));
                }
                None => text.push_str(token),
            }
        }
        Restated { text, replaced }
    }

    /// Whether WordNet reads `word` (lower case) as a noun at least as often as a verb: a
    /// subject ("someone", "a woman") before a verb.
    fn reads_as_noun(&self, word: &str) -> bool {
        let as_noun = self.wordnet.most_tagged(word, PartOfSpeech::Noun);
        as_noun.is_some() && as_noun >= self.wordnet.most_tagged(word, PartOfSpeech::Verb)
    }

    /// The caption verb, inflected, that replaces `word` (lower case), if any; `after_noun`:
    /// the word before it reads as a noun ([`Self::reads_as_noun`]).
    fn replacement(&self, word: &str, after_noun: bool) -> Option<String> {
        if self.known.contains(word) {
            return None;
        }
        let lemmas = self.wordnet.lemmas(word, PartOfSpeech::Verb);
        if lemmas.iter().any(|l| self.known.contains(l) || LIGHT_VERBS.contains(&l.as_str())) {
            return None;
        }
        // A third-person verb right after its subject ("a woman strides") is a verb however
        // often the word is a noun elsewhere.
        let subject_verb = after_noun && lemmas.iter().any(|l| Form::of(word, l) == Form::ThirdPerson);
        let as_verb = lemmas.iter().map(|l| self.wordnet.tagged(l, PartOfSpeech::Verb)).max();
        let as_other = [PartOfSpeech::Noun, PartOfSpeech::Adjective, PartOfSpeech::Adverb]
            .into_iter()
            .map(|pos| self.wordnet.most_tagged(word, pos))
            .max()
            .flatten();
        if !subject_verb && as_other > as_verb {
            return None;
        }
        lemmas.iter().find_map(|lemma| {
            let verb = self.nearest_caption_verb(lemma)?;
            let form = Form::of(word, lemma);
            let irregular = if form == Form::Past { self.wordnet.irregular_past(&verb) } else { Vec::new() };
            let spellings: Vec<String> = irregular.into_iter().chain(form.spellings(&verb)).collect();
            Some(spellings.iter().find(|s| self.known.contains(*s)).unwrap_or(&spellings[0]).clone())
        })
    }

    /// The first caption verb met in its own first sense searching `lemma`'s first sense of
    /// bodily motion breadth first through its words and [`HYPERNYM_LEVELS`] of hypernyms.
    /// Later senses are not searched: "land" (first: come to rest on the ground) reached
    /// "carry" through "bring ashore".
    fn nearest_caption_verb(&self, lemma: &str) -> Option<String> {
        let wordnet = &self.wordnet;
        wordnet
            .verb_senses(lemma)
            .iter()
            .find(|&&sense| BODILY_MOTION.contains(&wordnet.synset(sense).lexicographer_file))
            .and_then(|&sense| {
                let mut queue = VecDeque::from([(sense, 0)]);
                while let Some((row, level)) = queue.pop_front() {
                    let synset = wordnet.synset(row);
                    let first_sense_of = |w: &String| wordnet.verb_senses(w).first() == Some(&row);
                    if let Some(verb) =
                        synset.words.iter().find(|w| *w != lemma && self.verbs.contains(*w) && first_sense_of(w))
                    {
                        return Some(verb.clone());
                    }
                    if level < HYPERNYM_LEVELS {
                        queue.extend(synset.hypernyms.iter().map(|&h| (h, level + 1)));
                    }
                }
                None
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::text::wordnet::tests::tiny;

    fn restatement() -> Restatement {
        let captions = [
            "a person walks forward",
            "Walk Left: someone turns left at a slow pace",
            "walking",
            "a sharp turn",
            "sit",
            "run",
        ];
        Restatement::new(Arc::new(tiny()), &captions.map(String::from))
    }

    #[test]
    fn unknown_verbs_become_the_captions_verbs_in_the_same_form() {
        let r = restatement();
        let restated = r.restate("Someone ambles and veers off to their LEFT, ambling.");
        assert_eq!(restated.text, "Someone walks and turns off to their LEFT, walking.");
        let pairs: Vec<(&str, &str)> = restated.replaced.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect();
        assert_eq!(pairs, [("ambles", "walks"), ("veers", "turns"), ("ambling", "walking")]);
        assert_eq!(r.restate("Moseyed, then swerved").text, "Walked, then turned");
        assert_eq!(r.restate("someone sprinted").text, "someone ran", "irregular past");
    }

    #[test]
    fn a_third_person_verb_after_its_subject_is_a_verb_though_mostly_a_noun() {
        let r = restatement();
        assert_eq!(r.restate("a woman strides ahead").text, "a woman walks ahead");
        for prompt in ["someone takes long strides", "a woman, strides"] {
            assert_eq!(r.restate(prompt).text, prompt);
        }
    }

    #[test]
    fn only_the_first_sense_of_bodily_motion_is_searched() {
        // "land"'s first sense reaches no caption verb; its second would reach "walk".
        let r = restatement();
        assert_eq!(r.restate("someone jumps, landing softly").text, "someone jumps, landing softly");
    }

    #[test]
    fn a_word_read_more_often_as_an_adjective_is_kept() {
        // "full" is a rare verb of bodily motion (full cloth) reaching "walk" here.
        assert_eq!(restatement().restate("someone runs at full speed").text, "someone runs at full speed");
    }

    #[test]
    fn known_light_noun_like_and_unrelated_words_are_kept() {
        let r = restatement();
        for prompt in [
            "a person walks forward",    // every word a caption's
            "someone paces ahead",       // "pace" is a caption word
            "someone keeps one foot up", // a light verb; "foot" is tagged more as a noun
            "someone gallops",           // reaches {ride, sit}, not the first sense of "sit"
            "someone travels",           // only a light verb above it
            "a sofa",                    // not a verb
            "",
        ] {
            let restated = r.restate(prompt);
            assert_eq!(restated.text, prompt);
            assert!(restated.replaced.is_empty(), "{restated:?}");
        }
    }

    #[test]
    fn regular_inflections() {
        assert_eq!(Form::ThirdPerson.spellings("carry")[0], "carries");
        assert_eq!(Form::ThirdPerson.spellings("crouch")[0], "crouches");
        assert_eq!(Form::Gerund.spellings("stride")[0], "striding");
        assert_eq!(Form::Gerund.spellings("hop")[1], "hopping");
        assert_eq!(Form::Past.spellings("hurry")[0], "hurried");
        assert_eq!(Form::of("ran", "run"), Form::Past);
    }
}
