//! WordNet 3.0's verbs (Princeton University; `fixtures/text/wordnet/`, with its licence and
//! provenance): each verb lemma's senses in WordNet's order (most often tagged first), each
//! sense's synset (its words, lexicographer file and hypernyms), the irregular forms, and how
//! often a lemma was tagged as a verb, a noun, an adjective and an adverb in WordNet's
//! sense-tagged texts. With WordNet's `morphy` ([`WordNet::lemmas`]) a word is brought back to
//! its lemmas. What [`super::restatement`] reads to restate a prompt's unknown verbs in a
//! prior's caption words.
//!
//! The files are WordNet's own database format (`wndb(5WN)`), gzipped: `data.verb`,
//! `index.verb`, `verb.exc`, `index.noun`, `noun.exc`, `index.adj`, `adj.exc`, `index.adv`.
//! Lines starting with two spaces are the licence header.

use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

use crate::files::FileError;
use crate::limits::WORDNET_FILE_BYTES as FILE_BYTES;

/// The folder of the WordNet files under the text models folder (`fixtures/text/wordnet`).
pub const FOLDER: &str = "wordnet";

/// Lexicographer file numbers of verbs of bodily motion (WordNet's `lexnames`): `verb.body`,
/// `verb.contact` (sit, stand, crouch, carry) and `verb.motion` (walk, run, jump, turn, crawl).
pub const BODILY_MOTION: [u8; 3] = [29, 35, 38];

/// A part of speech this module reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PartOfSpeech {
    /// Verbs: senses, synsets and tagged counts.
    Verb,
    /// Nouns: lemmas and tagged counts only.
    Noun,
    /// Adjectives: lemmas and tagged counts only.
    Adjective,
    /// Adverbs: lemmas and tagged counts only.
    Adverb,
}

/// One verb synset.
#[derive(Debug, Clone, PartialEq)]
pub struct Synset {
    /// Its words, lower case, multi-word ones joined by `_` as WordNet writes them.
    pub words: Vec<String>,
    /// Its lexicographer file number (e.g. 38, `verb.motion`).
    pub lexicographer_file: u8,
    /// Rows of its hypernyms in [`WordNet::synset`]'s numbering.
    pub hypernyms: Vec<usize>,
}

/// A lemma of the index: its senses in WordNet's order and how often it was tagged.
#[derive(Debug, Clone, Default)]
struct Lemma {
    senses: Vec<usize>,
    tagged: u32,
}

/// A part of speech's index and irregular forms.
#[derive(Debug, Clone, Default)]
struct Index {
    lemmas: HashMap<String, Lemma>,
    /// Irregular form → its lemmas.
    exceptions: HashMap<String, Vec<String>>,
}

/// WordNet's verbs, and its noun, adjective and adverb lemmas with their tagged counts
/// ([module doc](self)).
#[derive(Debug, Clone)]
pub struct WordNet {
    synsets: Vec<Synset>,
    verbs: Index,
    /// Verb lemma → its irregular forms (`verb.exc` inverted), in the file's order.
    verb_forms: HashMap<String, Vec<String>>,
    nouns: Index,
    adjectives: Index,
    adverbs: Index,
}

/// WordNet's detachment rules (`morphy`): an ending and what replaces it.
const VERB_ENDINGS: [(&str, &str); 8] =
    [("s", ""), ("ies", "y"), ("es", "e"), ("es", ""), ("ed", "e"), ("ed", ""), ("ing", "e"), ("ing", "")];
const NOUN_ENDINGS: [(&str, &str); 8] =
    [("s", ""), ("ses", "s"), ("xes", "x"), ("zes", "z"), ("ches", "ch"), ("shes", "sh"), ("men", "man"), ("ies", "y")];
const ADJECTIVE_ENDINGS: [(&str, &str); 4] = [("er", ""), ("est", ""), ("er", "e"), ("est", "e")];

impl Index {
    fn new(mut lemmas: HashMap<String, Lemma>, exceptions: Vec<(String, Vec<String>)>) -> Self {
        lemmas.shrink_to_fit();
        Self { lemmas, exceptions: exceptions.into_iter().collect() }
    }
}

/// Lemma → its irregular forms, in the order of `exceptions` (form → lemmas).
fn irregular_forms(exceptions: &[(String, Vec<String>)]) -> HashMap<String, Vec<String>> {
    let mut forms: HashMap<String, Vec<String>> = HashMap::new();
    for (form, of) in exceptions {
        for lemma in of {
            forms.entry(lemma.clone()).or_default().push(form.clone());
        }
    }
    forms
}

impl WordNet {
    /// Reads the eight gzipped files from `dir` (`fixtures/text/wordnet`). Errors name the file
    /// and the line.
    pub fn load(dir: &Path) -> Result<Self, FileError> {
        let read = |name: &str| -> Result<(std::path::PathBuf, String), FileError> {
            let path = dir.join(format!("{name}.gz"));
            let packed = crate::files::read_bytes(&path, &FILE_BYTES)?;
            let mut text = String::new();
            flate2::read::GzDecoder::new(packed.as_slice())
                .take(FILE_BYTES.max + 1)
                .read_to_string(&mut text)
                .map_err(|e| FileError::format(&path, format!("not gzipped UTF-8 text: {e}")))?;
            FILE_BYTES.check_stream(text.len() as u64, path.display())?;
            Ok((path, text))
        };
        let parts =
            ["data.verb", "index.verb", "verb.exc", "index.noun", "noun.exc", "index.adj", "adj.exc", "index.adv"]
                .map(read);
        let [data_verb, index_verb, verb_exc, index_noun, noun_exc, index_adj, adj_exc, index_adv] = parts;
        let (data_verb, index_verb, verb_exc, index_noun, noun_exc, index_adj, adj_exc, index_adv) =
            (data_verb?, index_verb?, verb_exc?, index_noun?, noun_exc?, index_adj?, adj_exc?, index_adv?);
        fn at(path: &Path) -> impl Fn(String) -> FileError + '_ {
            move |message| FileError::format(path, message)
        }
        let (synsets, offsets) = parse_data(&data_verb.1).map_err(at(&data_verb.0))?;
        let verb_exceptions = parse_exceptions(&verb_exc.1).map_err(at(&verb_exc.0))?;
        let verb_forms = irregular_forms(&verb_exceptions);
        let verbs = Index::new(parse_index(&index_verb.1, Some(&offsets)).map_err(at(&index_verb.0))?, verb_exceptions);
        let tagged_only = |index: &(std::path::PathBuf, String), exceptions: Option<&(std::path::PathBuf, String)>| {
            let lemmas = parse_index(&index.1, None).map_err(at(&index.0))?;
            let exceptions = match exceptions {
                Some((path, text)) => parse_exceptions(text).map_err(at(path))?,
                None => Vec::new(),
            };
            Ok::<_, FileError>(Index::new(lemmas, exceptions))
        };
        let nouns = tagged_only(&index_noun, Some(&noun_exc))?;
        let adjectives = tagged_only(&index_adj, Some(&adj_exc))?;
        let adverbs = tagged_only(&index_adv, None)?;
        Ok(Self { synsets, verbs, verb_forms, nouns, adjectives, adverbs })
    }

    fn index(&self, pos: PartOfSpeech) -> &Index {
        match pos {
            PartOfSpeech::Verb => &self.verbs,
            PartOfSpeech::Noun => &self.nouns,
            PartOfSpeech::Adjective => &self.adjectives,
            PartOfSpeech::Adverb => &self.adverbs,
        }
    }

    /// The lemmas `word` (lower case) may be an inflection of as `pos` (WordNet's `morphy`):
    /// its irregular forms, the word itself, then each detachment rule whose result is a lemma;
    /// without repeats, in that order. Empty for a word WordNet does not know as `pos`.
    pub fn lemmas(&self, word: &str, pos: PartOfSpeech) -> Vec<String> {
        let index = self.index(pos);
        let endings = match pos {
            PartOfSpeech::Verb => &VERB_ENDINGS[..],
            PartOfSpeech::Noun => &NOUN_ENDINGS[..],
            PartOfSpeech::Adjective => &ADJECTIVE_ENDINGS[..],
            PartOfSpeech::Adverb => &[][..],
        };
        let mut found: Vec<String> = index.exceptions.get(word).cloned().unwrap_or_default();
        let detached = endings.iter().filter_map(|(ending, by)| {
            word.strip_suffix(ending).filter(|stem| !stem.is_empty()).map(|stem| format!("{stem}{by}"))
        });
        for lemma in std::iter::once(word.to_owned()).chain(detached) {
            if index.lemmas.contains_key(&lemma) && !found.contains(&lemma) {
                found.push(lemma);
            }
        }
        found
    }

    /// How often `lemma` was tagged as `pos` in WordNet's sense-tagged texts (0 for an unknown one).
    pub fn tagged(&self, lemma: &str, pos: PartOfSpeech) -> u32 {
        self.index(pos).lemmas.get(lemma).map_or(0, |l| l.tagged)
    }

    /// How often `word`'s lemmas as `pos` were tagged at most: `None` when WordNet does not know
    /// it as `pos`.
    pub fn most_tagged(&self, word: &str, pos: PartOfSpeech) -> Option<u32> {
        self.lemmas(word, pos).iter().map(|l| self.tagged(l, pos)).max()
    }

    /// The irregular past forms of the verb `lemma` in `verb.exc`'s order ("bend": "bent";
    /// its "-ing" and "-s" forms left out); empty for a regular verb.
    pub fn irregular_past(&self, lemma: &str) -> Vec<String> {
        let forms = self.verb_forms.get(lemma).map_or(&[][..], Vec::as_slice);
        forms.iter().filter(|f| !f.ends_with("ing") && !f.ends_with('s')).cloned().collect()
    }

    /// The verb senses of `lemma` in WordNet's order, as rows for [`Self::synset`].
    pub fn verb_senses(&self, lemma: &str) -> &[usize] {
        self.verbs.lemmas.get(lemma).map_or(&[], |l| &l.senses)
    }

    /// The verb synset at `row`.
    pub fn synset(&self, row: usize) -> &Synset {
        &self.synsets[row]
    }
}

/// The lines of a database file after its licence header, numbered from 1.
fn body(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().map(|(i, l)| (i + 1, l)).filter(|(_, l)| !l.starts_with("  ") && !l.trim().is_empty())
}

/// `data.verb`: the synsets in file order and each one's byte offset → row.
fn parse_data(text: &str) -> Result<(Vec<Synset>, HashMap<u64, usize>), String> {
    let mut synsets = Vec::new();
    let mut offsets = HashMap::new();
    let mut pointers: Vec<Vec<u64>> = Vec::new();
    for (line, content) in body(text) {
        let bad = |what: &str| format!("line {line}: {what}");
        let fields: Vec<&str> = content.split(" | ").next().unwrap_or("").split_whitespace().collect();
        let field = |k: usize| fields.get(k).copied().ok_or_else(|| bad("the synset line ends early"));
        let offset: u64 = field(0)?.parse().map_err(|_| bad("the synset offset is not a number"))?;
        let lexicographer_file: u8 = field(1)?.parse().map_err(|_| bad("the lexicographer file is not a number"))?;
        let words = usize::from_str_radix(field(3)?, 16).map_err(|_| bad("the word count is not hexadecimal"))?;
        let words = (0..words).map(|k| field(4 + 2 * k).map(str::to_lowercase)).collect::<Result<Vec<_>, _>>()?;
        let mut k = 4 + 2 * words.len();
        let count: usize = field(k)?.parse().map_err(|_| bad("the pointer count is not a number"))?;
        k += 1;
        let mut hypernyms = Vec::new();
        for _ in 0..count {
            let (symbol, target, pos) = (field(k)?, field(k + 1)?, field(k + 2)?);
            if (symbol == "@" || symbol == "@i") && pos == "v" {
                hypernyms.push(target.parse().map_err(|_| bad("a pointer's offset is not a number"))?);
            }
            k += 4;
        }
        if offsets.insert(offset, synsets.len()).is_some() {
            return Err(bad(&format!("synset offset {offset} appears twice")));
        }
        synsets.push(Synset { words, lexicographer_file, hypernyms: Vec::new() });
        pointers.push(hypernyms);
    }
    for (synset, targets) in synsets.iter_mut().zip(pointers) {
        synset.hypernyms = targets
            .iter()
            .map(|t| offsets.get(t).copied().ok_or_else(|| format!("a hypernym pointer names offset {t}, no synset")))
            .collect::<Result<_, _>>()?;
    }
    Ok((synsets, offsets))
}

/// `index.verb` / `index.noun`: lemma → senses (resolved through `offsets` when given; nouns
/// keep only their tagged count) and tagged count.
fn parse_index(text: &str, offsets: Option<&HashMap<u64, usize>>) -> Result<HashMap<String, Lemma>, String> {
    let mut lemmas = HashMap::new();
    for (line, content) in body(text) {
        let bad = |what: &str| format!("line {line}: {what}");
        let fields: Vec<&str> = content.split_whitespace().collect();
        let number = |k: usize| -> Result<usize, String> {
            fields
                .get(k)
                .ok_or_else(|| bad("the index line ends early"))?
                .parse()
                .map_err(|_| bad("a count is not a number"))
        };
        let pointer_kinds = number(3)?;
        let tagged = number(5 + pointer_kinds)? as u32;
        let senses = match offsets {
            Some(offsets) => fields
                .get(6 + pointer_kinds..)
                .ok_or_else(|| bad("the index line ends early"))?
                .iter()
                .map(|o| {
                    let o: u64 = o.parse().map_err(|_| bad("a synset offset is not a number"))?;
                    offsets.get(&o).copied().ok_or_else(|| bad(&format!("synset offset {o} is not in data.verb")))
                })
                .collect::<Result<_, _>>()?,
            None => Vec::new(),
        };
        lemmas.insert(fields[0].to_lowercase(), Lemma { senses, tagged });
    }
    Ok(lemmas)
}

/// `verb.exc` / `noun.exc`: each irregular form and its lemmas, in the file's order.
fn parse_exceptions(text: &str) -> Result<Vec<(String, Vec<String>)>, String> {
    let mut exceptions = Vec::new();
    for (line, content) in body(text) {
        let mut fields = content.split_whitespace().map(str::to_lowercase);
        let form = fields.next().ok_or_else(|| format!("line {line}: empty"))?;
        let lemmas: Vec<String> = fields.collect();
        if lemmas.is_empty() {
            return Err(format!("line {line}: {form:?} has no lemma"));
        }
        exceptions.push((form, lemmas));
    }
    Ok(exceptions)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A WordNet of a few synsets in the database's own format (offsets are line keys here).
    pub(crate) fn tiny() -> WordNet {
        let data = "  1 This software and database is being provided\n\
            100 38 v 01 travel 0 000 | change location\n\
            200 38 v 01 walk 0 001 @ 100 v 0000 | use one's feet\n\
            300 38 v 02 amble 0 mosey 0 001 @ 200 v 0000 | walk leisurely\n\
            400 38 v 01 turn 0 001 @ 100 v 0000 | change direction\n\
            500 38 v 04 swerve 0 veer 0 curve 0 slew 0 001 @ 400 v 0000 | turn sharply\n\
            600 30 v 01 keep 0 000 | retain\n\
            700 31 v 01 pace 0 001 @ 200 v 0000 | measure by walking\n\
            800 35 v 02 foot 0 hoof 0 001 @ 200 v 0000 | go on foot\n\
            900 35 v 01 sit 0 000 | be seated\n\
            950 38 v 02 ride 0 sit 0 000 | sit and travel on the back of an animal\n\
            990 38 v 01 gallop 0 001 @ 950 v 0000 | ride at a gallop\n\
            1000 38 v 01 stride 0 001 @ 200 v 0000 | walk with long steps\n\
            1100 38 v 01 land 0 001 @ 100 v 0000 | come to rest on the ground\n\
            1200 35 v 01 land 0 001 @ 200 v 0000 | (a later sense reaching a caption verb)\n\
            1400 38 v 01 run 0 001 @ 100 v 0000 | move fast on foot\n\
            1500 38 v 01 sprint 0 001 @ 1400 v 0000 | run very fast\n\
            1600 35 v 01 full 0 001 @ 200 v 0000 | (a rare verb reaching a caption verb)\n";
        let (synsets, offsets) = parse_data(data).unwrap();
        let index_verb =
            "travel v 1 1 @ 1 0 100\nwalk v 1 1 @ 1 30 200\namble v 1 1 @ 1 1 300\nmosey v 1 1 @ 1 0 300\n\
            turn v 1 1 @ 1 40 400\nswerve v 1 1 @ 1 0 500\nveer v 1 1 @ 1 0 500\ncurve v 1 1 @ 1 0 500\n\
            slew v 1 1 @ 1 0 500\nkeep v 1 0 1 50 600\npace v 1 0 1 0 700\nfoot v 1 0 1 0 800\nhoof v 1 0 1 0 800\n\
            sit v 2 0 2 60 900 950\nride v 1 0 1 5 950\ngallop v 1 1 @ 1 0 990\nstride v 1 1 @ 1 0 1000\n\
            land v 2 1 @ 2 5 1100 1200\nrun v 1 1 @ 1 20 1400\nsprint v 1 1 @ 1 0 1500\n\
            full v 1 1 @ 1 0 1600\n";
        let verb_exceptions = parse_exceptions("ran run\n").unwrap();
        let verb_forms = irregular_forms(&verb_exceptions);
        let verbs = Index::new(parse_index(index_verb, Some(&offsets)).unwrap(), verb_exceptions);
        let nouns = Index::new(
            parse_index("walk n 1 0 1 3 1\nfoot n 1 0 1 90 2\nwoman n 1 0 1 2 3\nstride n 1 0 1 3 4\n", None).unwrap(),
            parse_exceptions("feet foot\n").unwrap(),
        );
        let adjectives =
            Index::new(parse_index("full a 1 0 1 6 1\n", None).unwrap(), parse_exceptions("fuller full\n").unwrap());
        let adverbs = Index::new(parse_index("ahead r 1 0 1 4 1\n", None).unwrap(), Vec::new());
        WordNet { synsets, verbs, verb_forms, nouns, adjectives, adverbs }
    }

    #[test]
    fn morphy_finds_the_lemmas_of_inflected_and_irregular_forms() {
        let wn = tiny();
        assert_eq!(wn.lemmas("ambles", PartOfSpeech::Verb), ["amble"]);
        assert_eq!(wn.lemmas("ambling", PartOfSpeech::Verb), ["amble"]);
        assert_eq!(wn.lemmas("veered", PartOfSpeech::Verb), ["veer"]);
        assert_eq!(wn.lemmas("walks", PartOfSpeech::Verb), ["walk"]);
        assert_eq!(wn.lemmas("feet", PartOfSpeech::Noun), ["foot"]);
        assert!(wn.lemmas("sofa", PartOfSpeech::Verb).is_empty());
        assert_eq!(wn.tagged("foot", PartOfSpeech::Noun), 90);
        assert_eq!(wn.tagged("foot", PartOfSpeech::Verb), 0);
        assert_eq!(wn.most_tagged("strides", PartOfSpeech::Noun), Some(3));
        assert_eq!(wn.most_tagged("sofa", PartOfSpeech::Noun), None);
        assert_eq!(wn.irregular_past("run"), ["ran"]);
        assert!(wn.irregular_past("walk").is_empty());
        assert_eq!(wn.most_tagged("fuller", PartOfSpeech::Adjective), Some(6));
        assert_eq!(wn.most_tagged("ahead", PartOfSpeech::Adverb), Some(4));
    }

    #[test]
    fn synsets_carry_their_words_lexicographer_file_and_hypernyms() {
        let wn = tiny();
        let [sense] = wn.verb_senses("veer") else { panic!("one sense") };
        let synset = wn.synset(*sense);
        assert_eq!(synset.words, ["swerve", "veer", "curve", "slew"]);
        assert_eq!(synset.lexicographer_file, 38);
        assert_eq!(wn.synset(synset.hypernyms[0]).words, ["turn"]);
        assert!(wn.verb_senses("sofa").is_empty());
    }

    #[test]
    fn malformed_files_say_which_line() {
        let err = parse_data("100 38 v 01 walk 0 001 @ 999 v 0000 | x\n").unwrap_err();
        assert!(err.contains("offset 999"), "{err}");
        let err = parse_data("  licence\n100 38 v zz walk 0 000 | x\n").unwrap_err();
        assert!(err.starts_with("line 2:") && err.contains("hexadecimal"), "{err}");
        let err = parse_index("walk v 1\n", None).unwrap_err();
        assert!(err.starts_with("line 1:"), "{err}");
        let err = parse_exceptions("ran\n").unwrap_err();
        assert!(err.contains("no lemma"), "{err}");
    }

    #[test]
    fn loading_a_folder_without_the_files_names_the_missing_file() {
        let dir = tempfile::tempdir().unwrap();
        let err = WordNet::load(dir.path()).unwrap_err().to_string();
        assert!(err.contains("data.verb.gz"), "{err}");
    }
}
