//! Query benchmarks whose relevance is given by caption terms rather than by exact captions, so
//! that a query can be worded unlike anything in the library. The paraphrase benchmark ships
//! with the crate (`benchmarks/paraphrases.tsv`): queries that share no content word with the
//! captions of the clips they should find, some with typos.
//!
//! A query's relevance is a list of groups of terms: a clip is relevant when one of its
//! captions holds every term of one group, each as whole words, case and punctuation ignored
//! ("waves goodbye & sad | raises both hands").

/// The shipped paraphrase benchmark (tab-separated: query, relevance; `#` lines are comments).
pub const PARAPHRASES: &str = include_str!("../benchmarks/paraphrases.tsv");

/// Why a benchmark file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum BenchmarkError {
    /// A line is not `query<TAB>relevance`.
    #[error("line {line}: expected `query<TAB>relevance`, found {found:?}")]
    Malformed {
        /// 1-based line number.
        line: usize,
        /// The line.
        found: String,
    },
    /// A relevance with an empty group or term.
    #[error("line {line}: the relevance {relevance:?} has an empty group or term")]
    EmptyTerm {
        /// 1-based line number.
        line: usize,
        /// The relevance column.
        relevance: String,
    },
    /// The file holds no query.
    #[error("the benchmark holds no query")]
    Empty,
}

/// Which half of a benchmark a query is in: fusion is calibrated on the development half and
/// reported on the test half.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Half {
    /// Queries used to choose settings.
    Development,
    /// Queries only measured.
    Test,
}

/// Which clips answer a query: any group whose terms all appear in one caption.
#[derive(Clone, Debug, PartialEq)]
pub struct Relevance {
    groups: Vec<Vec<String>>,
}

impl Relevance {
    /// Parses `term & term | term`; `None` when a group or term is empty.
    pub fn parse(text: &str) -> Option<Relevance> {
        let groups: Vec<Vec<String>> =
            text.split('|').map(|group| group.split('&').map(normalise).collect::<Vec<String>>()).collect();
        let empty = groups.iter().flatten().any(|term| term.trim().is_empty());
        (!empty).then_some(Relevance { groups })
    }

    /// Whether a clip with these captions is relevant.
    pub fn accepts<S: AsRef<str>>(&self, captions: &[S]) -> bool {
        captions
            .iter()
            .map(|c| normalise(c.as_ref()))
            .any(|caption| self.groups.iter().any(|group| group.iter().all(|term| caption.contains(term.as_str()))))
    }
}

/// Lower-case words joined by single spaces and padded with one space each side, so that
/// substring search finds whole words only.
fn normalise(text: &str) -> String {
    let words: Vec<String> =
        text.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).map(str::to_lowercase).collect();
    format!(" {} ", words.join(" "))
}

/// One benchmark query.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchmarkQuery {
    /// The query as a user types it.
    pub text: String,
    /// Which clips answer it.
    pub relevance: Relevance,
    /// Its half: queries alternate, development first, in file order.
    pub half: Half,
}

/// Reads a benchmark file: a header line `query<TAB>relevance`, then one query per line;
/// blank lines and lines starting with `#` are skipped.
pub fn parse(text: &str) -> Result<Vec<BenchmarkQuery>, BenchmarkError> {
    let mut queries = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') || trimmed == "query\trelevant" {
            continue;
        }
        let Some((query, relevance)) = line.split_once('\t') else {
            return Err(BenchmarkError::Malformed { line: line_no, found: line.to_string() });
        };
        if query.trim().is_empty() || relevance.contains('\t') {
            return Err(BenchmarkError::Malformed { line: line_no, found: line.to_string() });
        }
        let relevance = Relevance::parse(relevance)
            .ok_or_else(|| BenchmarkError::EmptyTerm { line: line_no, relevance: relevance.to_string() })?;
        let half = if queries.len() % 2 == 0 { Half::Development } else { Half::Test };
        queries.push(BenchmarkQuery { text: query.trim().to_string(), relevance, half });
    }
    if queries.is_empty() {
        return Err(BenchmarkError::Empty);
    }
    Ok(queries)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terms_match_whole_words_in_one_caption() {
        let r = Relevance::parse("waves goodbye & sad | man runs").unwrap();
        assert!(r.accepts(&["a person waves goodbye with both hands in a sad manner"]));
        assert!(r.accepts(&["A MAN runs."]));
        // Every term of a group in the same caption, and whole words only.
        assert!(!r.accepts(&["a person waves goodbye", "a sad person walks"]));
        assert!(!r.accepts(&["a woman runs upright"]));
        assert!(!r.accepts(&["a person waves goodbye happily"]));
        assert!(Relevance::parse("walks | ").is_none());
        assert!(Relevance::parse("walks & ").is_none());
    }

    #[test]
    fn halves_alternate_and_bad_lines_name_their_number() {
        let text = "# comment\nquery\trelevant\none\twalks\ntwo\truns\n\nthree\tbows\n";
        let q = parse(text).unwrap();
        assert_eq!(
            q.iter().map(|q| (q.text.as_str(), q.half)).collect::<Vec<_>>(),
            [("one", Half::Development), ("two", Half::Test), ("three", Half::Development)]
        );
        assert!(matches!(parse("query\trelevant\nno tab here\n"), Err(BenchmarkError::Malformed { line: 2, .. })));
        assert!(matches!(parse("a\tb | \n"), Err(BenchmarkError::EmptyTerm { line: 1, .. })));
        assert!(matches!(parse("# nothing\n"), Err(BenchmarkError::Empty)));
    }

    #[test]
    fn the_shipped_benchmark_parses_with_two_hundred_queries() {
        let q = parse(PARAPHRASES).unwrap();
        assert!(q.len() >= 200, "{} queries", q.len());
        let dev = q.iter().filter(|q| q.half == Half::Development).count();
        assert_eq!(dev, q.len().div_ceil(2));
    }
}
