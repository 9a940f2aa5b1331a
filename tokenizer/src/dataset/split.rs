//! The dataset splits of `../shared/docs/EVAL.md`: `zero-shot` is every clip of the Quaternius
//! characters Spider, Snake, Snake_angry and Stag (topologies found nowhere else); `test` is
//! 15% of the other clips, chosen by a fixed hash of the clip path; `train` is the rest.

use std::fmt;

/// Which split a clip belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Split {
    /// Used for training.
    Train,
    /// Held out for evaluation.
    Test,
    /// Skeletons never seen in training.
    ZeroShot,
}

impl Split {
    /// The split's name as stored and printed.
    pub fn as_str(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
            Split::ZeroShot => "zero-shot",
        }
    }

    /// Parses a stored split name.
    pub fn parse(name: &str) -> Option<Split> {
        [Split::Train, Split::Test, Split::ZeroShot].into_iter().find(|s| s.as_str() == name)
    }
}

impl fmt::Display for Split {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The Quaternius characters held out as zero-shot skeletons.
pub const ZERO_SHOT_CHARACTERS: [&str; 4] = ["Spider", "Snake", "Snake_angry", "Stag"];

/// The share of clips (per source, in expectation) in the test split.
pub const TEST_SHARE: f64 = 0.15;

/// The split of the clip at `path` (relative to the data folder, `/`-separated, as in
/// `manifest.tsv`; a glTF animation is `file.glb#Animation`).
pub fn split_of(path: &str) -> Split {
    if is_zero_shot(path) {
        return Split::ZeroShot;
    }
    let hash = blake3::hash(path.as_bytes());
    let word = u64::from_le_bytes(hash.as_bytes()[..8].try_into().expect("8 bytes"));
    if (word as f64) < TEST_SHARE * u64::MAX as f64 { Split::Test } else { Split::Train }
}

/// The Quaternius character of a path: the file name up to `__` (BVH conversions name clips
/// `Character__Animation`) or up to its extension (`Character.glb`).
fn quaternius_character(path: &str) -> Option<&str> {
    if !path.split('/').any(|part| part == "quaternius") {
        return None;
    }
    let file = path.rsplit('/').next()?;
    let file = file.split('#').next()?;
    Some(match file.find("__") {
        Some(i) => &file[..i],
        None => file.split('.').next()?,
    })
}

fn is_zero_shot(path: &str) -> bool {
    quaternius_character(path).is_some_and(|c| ZERO_SHOT_CHARACTERS.contains(&c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_shot_characters_by_file_name() {
        assert_eq!(split_of("quaternius/bvh/easy_enemies_pack/Spider__Spider_Walk.bvh.gz"), Split::ZeroShot);
        assert_eq!(split_of("quaternius/bvh/easy_enemies_pack/Snake_angry__Snake_Idle.bvh.gz"), Split::ZeroShot);
        assert_eq!(split_of("quaternius/glb/animals_pack/Stag.glb#AnimalArmature|Walk"), Split::ZeroShot);
        // Stag's cousin Deer is not held out, nor a Spider outside the Quaternius set.
        assert_ne!(split_of("quaternius/bvh/animals_pack/Deer__Walk.bvh.gz"), Split::ZeroShot);
        assert_ne!(split_of("mydata/Spider__Walk.bvh"), Split::ZeroShot);
    }

    #[test]
    fn the_test_share_is_about_fifteen_percent_and_stable() {
        let paths: Vec<String> = (0..20_000).map(|i| format!("cmu/{i:05}.bvh.gz")).collect();
        let test = paths.iter().filter(|p| split_of(p) == Split::Test).count();
        let share = test as f64 / paths.len() as f64;
        assert!((share - 0.15).abs() < 0.01, "{share}");
        // The hash is fixed: this path has always been in the test split.
        assert_eq!(split_of("cmu/00003.bvh.gz"), split_of("cmu/00003.bvh.gz"));
        assert_eq!(Split::parse("zero-shot"), Some(Split::ZeroShot));
    }
}
