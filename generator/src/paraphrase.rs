//! Caption augmentation: the corpus's captions are short and templated ("a person walks in an
//! angry manner"), so a generator trained on them alone learns their wording, not their sense.
//! Each caption gets reworded variants: phrases swapped for others of their synonym group (who
//! moves, how, which way, in what mood), a word dropped now and then. Training draws among a caption and its variants; what users type
//! then lands nearer the motion it means.
//!
//! The groups are general English written for the corpus's actions and styles; none of their
//! words appears in the held-out prompts that `anymo eval prompts` measures with (a test checks
//! it), so that figure measures wording the model never saw.

use rand::Rng;
use rand::seq::IndexedRandom;

/// Groups of interchangeable phrases. A caption's phrase (whole words, longest first) may be
/// swapped for any other of its group.
pub const SYNONYMS: &[&[&str]] = &[
    // Who moves.
    &["person", "human", "man", "woman", "someone", "adult", "boy", "girl", "player", "youngster"],
    &["man", "male", "bloke"],
    &["woman", "female", "girl"],
    &["character", "animated character", "game character", "hero"],
    &["horse", "foal", "filly", "equine", "nag"],
    &["dog", "doggy", "pooch", "doggo", "cur"],
    &["husky dog", "husky", "sled dog"],
    &["shiba inu dog", "shiba inu", "shiba"],
    &["wolf", "timber wolf", "wild dog"],
    &["deer", "doe", "fawn", "roe"],
    &["cow", "cattle", "heifer"],
    &["bull", "ox", "bullock"],
    &["donkey", "burro", "ass"],
    &["large monster", "huge monster", "giant creature", "brute"],
    // Getting about.
    &["walks", "strides", "roams", "rambles", "tramps", "is walking", "is out walking"],
    &["walk", "stride", "ramble"],
    &["runs", "jogs", "darts", "lopes", "is running", "moves at a run"],
    &["dashes forward", "darts forward", "dashes"],
    &["gallops", "canters", "runs at a gallop", "is galloping"],
    &["jumps", "skips", "pounces", "jumps into the air"],
    &["forward", "forwards", "straight"],
    &["backwards", "backward", "in a backward direction"],
    &["walks backwards", "walks backward", "moves backward"],
    &["sideways", "crabwise", "sidelong"],
    &["to the left", "leftward"],
    &["to the right", "rightward"],
    &["turns left", "turns to the left", "swivels left", "spins left", "rotates left"],
    &["turns right", "turns to the right", "swivels right", "spins right", "rotates right"],
    // Hands and gestures.
    &["raises", "lifts", "holds up", "hoists"],
    &["hand", "arm"],
    &["hands", "arms"],
    &["both hands", "both arms", "each hand"],
    &["waves", "gestures"],
    &["waves goodbye", "gestures goodbye", "waves a goodbye"],
    &["waves hello", "gestures hello", "waves a hello"],
    &["bows", "bends forward", "bends at the waist", "curtsies", "leans forward deeply"],
    &["kicks", "kicks out", "lashes out with a leg", "strikes with the leg"],
    &["punches", "jabs", "hits out", "lands a punch"],
    &["stands idle", "stands there", "stays in place", "does nothing", "pauses"],
    &["idle", "inactive", "doing nothing"],
    &["falls down", "collapses", "tumbles", "drops to the ground"],
    &["dies", "collapses dead", "perishes", "is killed"],
    &["attacks", "strikes", "assaults", "lunges"],
    &["eats", "grazes", "feeds", "munches"],
    // Mood and manner.
    &["angry", "furious", "mad", "irate", "annoyed"],
    &["happy", "merry", "joyful", "glad"],
    &["sad", "sorrowful", "gloomy", "unhappy", "melancholy"],
    &["tired", "worn out", "fatigued", "sleepy"],
    &["exhausted", "drained", "spent", "worn out"],
    &["proud", "confident", "dignified"],
    &["old", "elderly", "aged", "senior"],
    &["youthful", "young", "lively"],
    &["childish", "infantile", "playful", "silly"],
    &["feminine", "girly", "womanly"],
    &["masculine", "manly", "macho"],
    &["unconfident", "insecure", "timid", "shy", "hesitant"],
    &["thuggish", "menacing", "tough", "rough"],
    &["musical", "rhythmic"],
    &["giant", "huge", "enormous"],
    &["active", "energetic", "vigorous"],
    &["neutral", "normal", "plain", "ordinary"],
    &["depressed", "dejected", "downcast"],
    &["sexy", "seductive", "sultry"],
    &["manner", "mood", "way", "fashion"],
    &["slow", "sluggish", "dawdling"],
    &["fast", "rapid", "swift"],
];

/// Words never dropped: without them a caption says nothing.
const KEEP: [&str; 4] = ["a", "an", "the", "its"];

/// How a caption is reworded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rewording {
    /// Chance that a phrase with synonyms is swapped.
    pub swap: f32,
    /// Chance that a variant drops one word.
    pub drop_word: f32,
}

impl Default for Rewording {
    fn default() -> Self {
        Rewording { swap: 0.7, drop_word: 0.2 }
    }
}

/// Up to `count` distinct variants of `caption` (lowercased), none equal to it; fewer when the
/// caption has little to reword.
pub fn variants(caption: &str, count: usize, rewording: Rewording, rng: &mut impl Rng) -> Vec<String> {
    let original = caption.trim().to_lowercase();
    let mut out: Vec<String> = Vec::with_capacity(count);
    for _ in 0..count * 8 {
        if out.len() == count {
            break;
        }
        let candidate = reword(&original, rewording, rng);
        if candidate != original && !out.contains(&candidate) {
            out.push(candidate);
        }
    }
    out
}

/// One rewording of a lowercase caption.
fn reword(caption: &str, rewording: Rewording, rng: &mut impl Rng) -> String {
    let words: Vec<&str> = caption.split_whitespace().collect();
    let mut out: Vec<String> = Vec::with_capacity(words.len());
    let mut i = 0;
    while i < words.len() {
        match longest_phrase(&words[i..]) {
            Some((length, group)) if rng.random::<f32>() < rewording.swap => {
                let own = words[i..i + length].join(" ");
                let others: Vec<&&str> = group.iter().filter(|p| **p != own).collect();
                let chosen = others.choose(rng).map_or(own.clone(), |p| p.to_string());
                out.extend(chosen.split(' ').map(String::from));
                i += length;
            }
            Some((length, _)) => {
                out.extend(words[i..i + length].iter().map(|w| w.to_string()));
                i += length;
            }
            None => {
                out.push(words[i].to_string());
                i += 1;
            }
        }
    }
    if out.len() > 3 && rng.random::<f32>() < rewording.drop_word {
        let droppable: Vec<usize> = (0..out.len()).filter(|&k| !KEEP.contains(&out[k].as_str())).collect();
        if let Some(&k) = droppable.choose(rng) {
            out.remove(k);
        }
    }
    fix_articles(&mut out);
    out.join(" ")
}

/// The longest phrase of [`SYNONYMS`] that `words` start with: its length in words and group.
fn longest_phrase(words: &[&str]) -> Option<(usize, &'static [&'static str])> {
    let mut best: Option<(usize, &'static [&'static str])> = None;
    for group in SYNONYMS {
        for phrase in group.iter() {
            let parts: Vec<&str> = phrase.split(' ').collect();
            let fits = parts.len() <= words.len() && parts.iter().zip(words).all(|(p, w)| p == w);
            if fits && best.is_none_or(|(length, _)| parts.len() > length) {
                best = Some((parts.len(), group));
            }
        }
    }
    best
}

/// "a" before a vowel becomes "an", and "an" before a consonant "a".
fn fix_articles(words: &mut [String]) {
    for k in 0..words.len().saturating_sub(1) {
        let vowel = words[k + 1].starts_with(['a', 'e', 'i', 'o', 'u']);
        if words[k] == "a" && vowel {
            words[k] = "an".into();
        } else if words[k] == "an" && !vowel {
            words[k] = "a".into();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn rng() -> rand_chacha::ChaCha8Rng {
        rand_chacha::ChaCha8Rng::seed_from_u64(7)
    }

    #[test]
    fn variants_swap_synonyms_keep_articles_right_and_differ() {
        let always = Rewording { swap: 1.0, drop_word: 0.0 };
        let out = variants("A person walks in an angry manner", 6, always, &mut rng());
        assert_eq!(out.len(), 6, "{out:?}");
        for v in &out {
            let words: Vec<&str> = v.split(' ').collect();
            assert!(!words.contains(&"person") && !words.contains(&"walks") && !words.contains(&"angry"), "{v}");
            assert!(!v.contains("manner"), "{v}");
            for pair in words.windows(2) {
                let vowel = pair[1].starts_with(['a', 'e', 'i', 'o', 'u']);
                let article = match pair[0] {
                    "a" => Some(false),
                    "an" => Some(true),
                    _ => None,
                };
                assert!(article.is_none_or(|an| an == vowel), "{v}");
            }
        }
        let mut sorted = out.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), out.len(), "distinct: {out:?}");
    }

    #[test]
    fn the_longest_phrase_wins_and_words_without_synonyms_stay() {
        let always = Rewording { swap: 1.0, drop_word: 0.0 };
        for v in variants("a person walks backwards", 5, always, &mut rng()) {
            // "walks backwards" is one phrase, swapped whole for another of its group: never
            // "strides backwards" from the shorter "walks".
            assert!(v.ends_with(" walks backward") || v.ends_with(" moves backward"), "{v}");
        }
        assert!(variants("zzz qqq", 3, always, &mut rng()).is_empty(), "nothing to reword");
        let never = Rewording { swap: 0.0, drop_word: 0.0 };
        assert!(variants("a person runs", 3, never, &mut rng()).is_empty());
    }

    #[test]
    fn a_dropped_word_is_never_an_article() {
        let drop = Rewording { swap: 0.0, drop_word: 1.0 };
        let out = variants("a person raises the left hand", 4, drop, &mut rng());
        assert!(!out.is_empty());
        for v in &out {
            assert_eq!(v.split(' ').count(), 5, "{v}");
            assert!(v.starts_with("a ") && v.contains(" the "), "{v}");
        }
    }
}
