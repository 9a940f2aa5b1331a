//! Metadata filters. One definition serves every retriever: a filter is turned into the set of
//! clip ids it allows once per query, and BM25 and both vector scans consult that set.

use crate::document::ClipDocument;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Restrictions on which clips a search may return. Text comparisons ignore case.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Filter {
    /// Exactly this licence (`CC0-1.0`).
    pub licence: Option<String>,
    /// Subjects containing all of these words: `dog` allows `husky dog` and `shiba inu dog`.
    pub subject: Option<String>,
    /// Skeletons whose fingerprint starts with this.
    pub skeleton: Option<String>,
    /// Sources starting with this: `quaternius` allows every Quaternius pack.
    pub source: Option<String>,
    /// Clips at least this many seconds long.
    pub min_seconds: Option<f64>,
    /// Clips at most this many seconds long.
    pub max_seconds: Option<f64>,
}

/// Why a filter cannot be applied.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FilterError {
    /// A text restriction that is empty or only spaces.
    #[error("the {0} filter is empty")]
    Empty(&'static str),
    /// A duration bound that is negative or not a number.
    #[error("the {0} duration bound must be a non-negative number of seconds")]
    Bound(&'static str),
    /// A duration range with its minimum above its maximum.
    #[error("the shortest duration ({min} s) is longer than the longest ({max} s)")]
    Range {
        /// The minimum asked.
        min: f64,
        /// The maximum asked.
        max: f64,
    },
}

impl Filter {
    /// Whether the filter restricts nothing.
    pub fn is_empty(&self) -> bool {
        *self == Filter::default()
    }

    /// Checks that the filter can be applied.
    pub fn validate(&self) -> Result<(), FilterError> {
        for (name, value) in [
            ("licence", &self.licence),
            ("subject", &self.subject),
            ("skeleton", &self.skeleton),
            ("source", &self.source),
        ] {
            if value.as_ref().is_some_and(|v| v.trim().is_empty()) {
                return Err(FilterError::Empty(name));
            }
        }
        for (name, bound) in [("shortest", self.min_seconds), ("longest", self.max_seconds)] {
            if bound.is_some_and(|b| !(b >= 0.0 && b.is_finite())) {
                return Err(FilterError::Bound(name));
            }
        }
        if let (Some(min), Some(max)) = (self.min_seconds, self.max_seconds)
            && min > max
        {
            return Err(FilterError::Range { min, max });
        }
        Ok(())
    }

    /// Whether `clip` passes the filter.
    pub fn accepts(&self, clip: &ClipDocument) -> bool {
        self.compile().accepts(&FilterKey::of(clip))
    }

    /// The filter in the form [`FilterKey`]s are checked against (lower case, trimmed), so that
    /// checking many clips allocates nothing.
    pub fn compile(&self) -> CompiledFilter {
        let lower = |s: &Option<String>| s.as_ref().map(|s| s.trim().to_lowercase());
        CompiledFilter {
            licence: lower(&self.licence),
            subject: self.subject.as_ref().map(|s| s.split_whitespace().map(str::to_lowercase).collect()),
            skeleton: lower(&self.skeleton),
            source: lower(&self.source),
            min_seconds: self.min_seconds,
            max_seconds: self.max_seconds,
        }
    }
}

/// A clip's metadata as filters compare it: lower case, subject split into words.
#[derive(Clone, Debug)]
pub struct FilterKey {
    licence: String,
    subject: Vec<String>,
    skeleton: String,
    source: String,
    seconds: f64,
}

impl FilterKey {
    /// The key of `clip`.
    pub fn of(clip: &ClipDocument) -> FilterKey {
        FilterKey {
            licence: clip.licence.to_lowercase(),
            subject: clip.subject.split_whitespace().map(str::to_lowercase).collect(),
            skeleton: clip.skeleton.to_lowercase(),
            source: clip.source.to_lowercase(),
            seconds: clip.seconds,
        }
    }
}

/// A [`Filter`] ready to check many clips.
#[derive(Clone, Debug)]
pub struct CompiledFilter {
    licence: Option<String>,
    subject: Option<Vec<String>>,
    skeleton: Option<String>,
    source: Option<String>,
    min_seconds: Option<f64>,
    max_seconds: Option<f64>,
}

impl CompiledFilter {
    /// Whether a clip with this key passes.
    pub fn accepts(&self, key: &FilterKey) -> bool {
        self.licence.as_ref().is_none_or(|l| *l == key.licence)
            && self.subject.as_ref().is_none_or(|words| words.iter().all(|w| key.subject.contains(w)))
            && self.skeleton.as_ref().is_none_or(|s| key.skeleton.starts_with(s.as_str()))
            && self.source.as_ref().is_none_or(|s| key.source.starts_with(s.as_str()))
            && self.min_seconds.is_none_or(|m| key.seconds >= m)
            && self.max_seconds.is_none_or(|m| key.seconds <= m)
    }
}

/// The clip ids a filter allows, as a bitmap over ids (store ids are small and dense, so the
/// bitmap is a few kilobytes even for a large library).
/// `Allowed::all` is the unfiltered case and costs nothing to consult.
#[derive(Clone, Debug)]
pub struct Allowed(Option<Arc<Vec<u64>>>);

impl Allowed {
    /// Every id.
    pub fn all() -> Allowed {
        Allowed(None)
    }

    /// Exactly `ids`.
    pub fn only(ids: impl IntoIterator<Item = u64>) -> Allowed {
        let mut words: Vec<u64> = Vec::new();
        for id in ids {
            let word = (id / 64) as usize;
            if word >= words.len() {
                words.resize(word + 1, 0);
            }
            words[word] |= 1 << (id % 64);
        }
        Allowed(Some(Arc::new(words)))
    }

    /// Whether every id is allowed.
    pub fn is_all(&self) -> bool {
        self.0.is_none()
    }

    /// Whether `id` is allowed.
    pub fn contains(&self, id: u64) -> bool {
        match &self.0 {
            None => true,
            Some(words) => words.get((id / 64) as usize).is_some_and(|w| w & (1 << (id % 64)) != 0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clip(subject: &str, source: &str, licence: &str, seconds: f64) -> ClipDocument {
        ClipDocument {
            id: 1,
            path: "x.bvh".into(),
            captions: vec![],
            subject: subject.into(),
            source: source.into(),
            licence: licence.into(),
            skeleton: "ab12cd".into(),
            joint_labels: vec![],
            seconds,
        }
    }

    #[test]
    fn each_restriction_means_what_it_says() {
        let husky = clip("husky dog", "quaternius-animals_pack", "CC0-1.0", 1.5);
        let person = clip("person", "bandai-namco-dataset-2", "CC-BY-NC-4.0", 4.0);
        let f = |f: Filter| (f.accepts(&husky), f.accepts(&person));
        assert_eq!(f(Filter::default()), (true, true));
        assert_eq!(f(Filter { subject: Some("Dog".into()), ..Filter::default() }), (true, false));
        assert_eq!(f(Filter { subject: Some("husky dog".into()), ..Filter::default() }), (true, false));
        assert_eq!(f(Filter { subject: Some("do".into()), ..Filter::default() }), (false, false));
        assert_eq!(f(Filter { licence: Some("cc0-1.0".into()), ..Filter::default() }), (true, false));
        assert_eq!(f(Filter { source: Some("bandai".into()), ..Filter::default() }), (false, true));
        assert_eq!(f(Filter { skeleton: Some("AB12".into()), ..Filter::default() }), (true, true));
        assert_eq!(f(Filter { skeleton: Some("b12".into()), ..Filter::default() }), (false, false));
        assert_eq!(f(Filter { min_seconds: Some(1.5), max_seconds: Some(3.0), ..Filter::default() }), (true, false));
        assert_eq!(f(Filter { min_seconds: Some(2.0), ..Filter::default() }), (false, true));
    }

    #[test]
    fn bad_filters_are_refused_with_the_reason() {
        let refuse = |f: Filter| f.validate().unwrap_err();
        assert_eq!(refuse(Filter { subject: Some("  ".into()), ..Filter::default() }), FilterError::Empty("subject"));
        assert_eq!(refuse(Filter { min_seconds: Some(-1.0), ..Filter::default() }), FilterError::Bound("shortest"));
        assert_eq!(refuse(Filter { max_seconds: Some(f64::NAN), ..Filter::default() }), FilterError::Bound("longest"));
        assert_eq!(
            refuse(Filter { min_seconds: Some(3.0), max_seconds: Some(2.0), ..Filter::default() }),
            FilterError::Range { min: 3.0, max: 2.0 }
        );
        assert!(Filter { min_seconds: Some(2.0), max_seconds: Some(2.0), ..Filter::default() }.validate().is_ok());
    }

    #[test]
    fn the_bitmap_holds_exactly_its_ids() {
        let allowed = Allowed::only([0, 63, 64, 1000]);
        let held: Vec<u64> = (0..1100).filter(|&i| allowed.contains(i)).collect();
        assert_eq!(held, vec![0, 63, 64, 1000]);
        assert!(!allowed.contains(u64::MAX));
        assert!(Allowed::all().contains(u64::MAX));
    }
}
