//! The full-text side: a tantivy index of clip documents, ranked by BM25 over captions (stemmed,
//! so "gallop" finds "gallops"; stop words left out), subject, path, source and joint labels, with highlighted caption
//! snippets. It is also where clip documents are stored: the set of documents committed here is
//! the set of clips the engine knows.

use crate::document::ClipDocument;
use crate::filter::Allowed;
use std::ops::Range;
use std::path::Path;
use tantivy::collector::{DocSetCollector, FilterCollector, TopDocs};
use tantivy::query::{AllQuery, Query, QueryParser};
use tantivy::schema::{
    FAST, Field, INDEXED, IndexRecordOption, STORED, STRING, Schema, TextFieldIndexing, TextOptions, Value,
};
use tantivy::snippet::SnippetGenerator;
use tantivy::tokenizer::{
    Language, LowerCaser, RemoveLongFilter, SimpleTokenizer, Stemmer, StopWordFilter, TextAnalyzer,
};
use tantivy::{DocAddress, Index, IndexReader, ReloadPolicy, TantivyDocument, Term};

/// The analyzer of the searchable text fields: words, lower case, English stop words out
/// ("a", "the", "then"), stemmed.
const ANALYZER: &str = "anymo_en";

/// Heap given to tantivy's single indexing thread (its minimum is 15 MB).
const WRITER_HEAP: usize = 64 << 20;

/// A caption with the spans that matched the query, for showing why a clip was found.
#[derive(Clone, Debug, PartialEq)]
pub struct Snippet {
    /// The caption.
    pub text: String,
    /// Byte ranges of matched words in `text`.
    pub highlights: Vec<Range<usize>>,
}

impl Snippet {
    /// The caption with each match wrapped in `open` and `close` (`<b>`/`</b>` for HTML,
    /// `*`/`*` for a terminal).
    pub fn marked(&self, open: &str, close: &str) -> String {
        let mut out = String::with_capacity(self.text.len() + 8 * self.highlights.len());
        let mut at = 0;
        for range in &self.highlights {
            out.push_str(&self.text[at..range.start]);
            out.push_str(open);
            out.push_str(&self.text[range.clone()]);
            out.push_str(close);
            at = range.end;
        }
        out.push_str(&self.text[at..]);
        out
    }
}

#[derive(Clone, Copy)]
struct Fields {
    id: Field,
    path: Field,
    captions: Field,
    subject: Field,
    source: Field,
    licence: Field,
    skeleton: Field,
    labels: Field,
    seconds: Field,
}

fn schema() -> (Schema, Fields) {
    let stemmed = TextOptions::default().set_stored().set_indexing_options(
        TextFieldIndexing::default().set_tokenizer(ANALYZER).set_index_option(IndexRecordOption::WithFreqsAndPositions),
    );
    let mut builder = Schema::builder();
    let fields = Fields {
        id: builder.add_u64_field("id", INDEXED | FAST | STORED),
        path: builder.add_text_field("path", stemmed.clone()),
        captions: builder.add_text_field("captions", stemmed.clone()),
        subject: builder.add_text_field("subject", stemmed.clone()),
        source: builder.add_text_field("source", stemmed.clone()),
        licence: builder.add_text_field("licence", STRING | STORED),
        skeleton: builder.add_text_field("skeleton", STRING | STORED),
        labels: builder.add_text_field("labels", stemmed),
        seconds: builder.add_f64_field("seconds", STORED),
    };
    (builder.build(), fields)
}

/// The tantivy index of clip documents.
pub struct TextIndex {
    index: Index,
    reader: IndexReader,
    fields: Fields,
    parser: QueryParser,
}

impl TextIndex {
    /// Opens the index in `dir`, creating an empty one if there is none. An index of another
    /// schema (an older anymo's) is replaced by an empty one: the index is derived from the
    /// store, and syncing fills it again.
    pub fn open(dir: &Path) -> tantivy::Result<TextIndex> {
        std::fs::create_dir_all(dir)?;
        let open = || Index::open_or_create(tantivy::directory::MmapDirectory::open(dir)?, schema().0);
        let index = match open() {
            Err(tantivy::TantivyError::SchemaError(_)) => {
                std::fs::remove_dir_all(dir)?;
                std::fs::create_dir_all(dir)?;
                open()?
            }
            other => other?,
        };
        TextIndex::from_index(index)
    }

    /// An index held in memory only (evaluation, tests).
    pub fn in_memory() -> TextIndex {
        TextIndex::from_index(Index::create_in_ram(schema().0)).expect("an in-memory index opens")
    }

    fn from_index(index: Index) -> tantivy::Result<TextIndex> {
        let (_, fields) = schema();
        let analyzer = TextAnalyzer::builder(SimpleTokenizer::default())
            .filter(RemoveLongFilter::limit(40))
            .filter(LowerCaser)
            .filter(StopWordFilter::new(Language::English).expect("tantivy has English stop words"))
            .filter(Stemmer::new(Language::English))
            .build();
        index.tokenizers().register(ANALYZER, analyzer);
        let reader = index.reader_builder().reload_policy(ReloadPolicy::Manual).try_into()?;
        let mut parser = QueryParser::for_index(
            &index,
            vec![fields.captions, fields.subject, fields.path, fields.source, fields.labels],
        );
        parser.set_field_boost(fields.captions, 2.0);
        parser.set_field_boost(fields.subject, 1.5);
        parser.set_field_boost(fields.path, 0.5);
        parser.set_field_boost(fields.source, 0.5);
        parser.set_field_boost(fields.labels, 0.25);
        Ok(TextIndex { index, reader, fields, parser })
    }

    /// Every committed document.
    pub fn documents(&self) -> tantivy::Result<Vec<ClipDocument>> {
        let searcher = self.reader.searcher();
        let addresses = searcher.search(&AllQuery, &DocSetCollector)?;
        let mut out = Vec::with_capacity(addresses.len());
        for address in addresses {
            out.push(self.document(&searcher.doc(address)?));
        }
        out.sort_by_key(|d| d.id);
        Ok(out)
    }

    fn document(&self, doc: &TantivyDocument) -> ClipDocument {
        let f = &self.fields;
        let text = |field| doc.get_first(field).and_then(|v| v.as_str()).unwrap_or_default().to_string();
        let all = |field| doc.get_all(field).filter_map(|v| v.as_str().map(String::from)).collect();
        ClipDocument {
            id: doc.get_first(f.id).and_then(|v| v.as_u64()).unwrap_or_default(),
            path: text(f.path),
            captions: all(f.captions),
            subject: text(f.subject),
            source: text(f.source),
            licence: text(f.licence),
            skeleton: text(f.skeleton),
            joint_labels: all(f.labels),
            seconds: doc.get_first(f.seconds).and_then(|v| v.as_f64()).unwrap_or_default(),
        }
    }

    /// Adds (or replaces, by id) `add` and deletes `remove`, in one commit: after a crash the
    /// index holds either all of it or none of it.
    pub fn write(&mut self, add: &[ClipDocument], remove: &[u64]) -> tantivy::Result<()> {
        if add.is_empty() && remove.is_empty() {
            return Ok(());
        }
        let f = self.fields;
        let mut writer = self.index.writer_with_num_threads::<TantivyDocument>(1, WRITER_HEAP)?;
        for id in remove.iter().copied().chain(add.iter().map(|d| d.id)) {
            writer.delete_term(Term::from_field_u64(f.id, id));
        }
        for d in add {
            let mut doc = TantivyDocument::new();
            doc.add_u64(f.id, d.id);
            doc.add_text(f.path, &d.path);
            d.captions.iter().for_each(|c| doc.add_text(f.captions, c));
            doc.add_text(f.subject, &d.subject);
            doc.add_text(f.source, &d.source);
            doc.add_text(f.licence, &d.licence);
            doc.add_text(f.skeleton, &d.skeleton);
            d.joint_labels.iter().for_each(|l| doc.add_text(f.labels, l));
            doc.add_f64(f.seconds, d.seconds);
            writer.add_document(doc)?;
        }
        writer.commit()?;
        writer.wait_merging_threads()?;
        self.reader.reload()
    }

    fn parse(&self, text: &str) -> Box<dyn Query> {
        // Lenient: a user's stray quote or colon searches the words instead of failing.
        self.parser.parse_query_lenient(text).0
    }

    /// The `limit` best BM25 matches of `text` among the allowed clips: (clip id, score), best
    /// first.
    pub fn search(&self, text: &str, allowed: &Allowed, limit: usize) -> tantivy::Result<Vec<(u64, f32)>> {
        if limit == 0 {
            return Ok(Vec::new());
        }
        let searcher = self.reader.searcher();
        let query = self.parse(text);
        let top_docs = TopDocs::with_limit(limit).order_by_score();
        // Unfiltered, tantivy can skip blocks that cannot make the top (block-max WAND); a
        // filter has to see every match.
        let top = if allowed.is_all() {
            searcher.search(&*query, &top_docs)?
        } else {
            let allowed = allowed.clone();
            searcher.search(
                &*query,
                &FilterCollector::new("id".to_string(), move |id: u64| allowed.contains(id), top_docs),
            )?
        };
        let mut columns = Vec::new();
        for reader in searcher.segment_readers() {
            columns.push(reader.fast_fields().u64("id")?);
        }
        Ok(top
            .into_iter()
            .filter_map(|(score, DocAddress { segment_ord, doc_id })| {
                columns[segment_ord as usize].first(doc_id).map(|id| (id, score))
            })
            .collect())
    }

    /// The share of `text`'s searchable words (after stop words and stemming) that at least one
    /// indexed clip holds in a searched field; 0 when the text has no searchable word. A query
    /// worded unlike the library shares few words with it, and its BM25 list is then made of
    /// incidental matches.
    pub fn known_share(&self, text: &str) -> tantivy::Result<f32> {
        let searcher = self.reader.searcher();
        let mut analyzer = self.index.tokenizer_for_field(self.fields.captions)?;
        let mut words = Vec::new();
        analyzer.token_stream(text).process(&mut |token| words.push(token.text.clone()));
        words.sort();
        words.dedup();
        let f = self.fields;
        let mut known = 0;
        for word in &words {
            for field in [f.captions, f.subject, f.path, f.source, f.labels] {
                if searcher.doc_freq(&Term::from_field_text(field, word))? > 0 {
                    known += 1;
                    break;
                }
            }
        }
        Ok(if words.is_empty() { 0.0 } else { known as f32 / words.len() as f32 })
    }

    /// Something that marks `text`'s words in captions.
    pub fn highlighter(&self, text: &str) -> tantivy::Result<Highlighter> {
        let searcher = self.reader.searcher();
        let query = self.parse(text);
        let mut generator = SnippetGenerator::create(&searcher, &*query, self.fields.captions)?;
        generator.set_max_num_chars(300);
        Ok(Highlighter(generator))
    }
}

/// Marks a query's words in captions.
pub struct Highlighter(SnippetGenerator);

impl Highlighter {
    /// The caption with the most matched words (the first caption when none matches), or
    /// `None` for a clip without captions.
    pub fn best(&self, captions: &[String]) -> Option<Snippet> {
        captions
            .iter()
            .map(|caption| {
                let snippet = self.0.snippet(caption);
                // The fragment is the whole caption when it fits (captions are short); otherwise
                // the ranges are relative to the fragment, which is then what is shown.
                let fragment_start = snippet.fragment_range().start;
                let text = if snippet.fragment().is_empty() { caption.clone() } else { snippet.fragment().to_string() };
                let highlights = if snippet.fragment().is_empty() {
                    Vec::new()
                } else {
                    snippet.highlighted().iter().map(|r| r.start - fragment_start..r.end - fragment_start).collect()
                };
                Snippet { text, highlights }
            })
            .enumerate()
            .max_by_key(|(i, s)| (s.highlights.len(), std::cmp::Reverse(*i)))
            .map(|(_, s)| s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(id: u64, subject: &str, caption: &str, licence: &str) -> ClipDocument {
        ClipDocument {
            id,
            path: format!("{subject}/{id}.bvh"),
            captions: vec![caption.to_string()],
            subject: subject.into(),
            source: "test-pack".into(),
            licence: licence.into(),
            skeleton: "f00d".into(),
            joint_labels: vec!["left foot".into()],
            seconds: id as f64,
        }
    }

    #[test]
    fn stems_filters_replaces_and_deletes() {
        let mut index = TextIndex::in_memory();
        index
            .write(
                &[
                    doc(1, "horse", "a horse gallops across the field", "CC0-1.0"),
                    doc(2, "person", "a person walks slowly", "CC-BY-4.0"),
                    doc(3, "donkey", "a donkey gallop", "CC0-1.0"),
                ],
                &[],
            )
            .unwrap();
        let ids = |hits: Vec<(u64, f32)>| hits.into_iter().map(|h| h.0).collect::<Vec<_>>();
        let mut hits = ids(index.search("galloping", &Allowed::all(), 10).unwrap());
        hits.sort();
        assert_eq!(hits, vec![1, 3]);
        assert_eq!(ids(index.search("galloping", &Allowed::only([3]), 10).unwrap()), vec![3]);
        assert_eq!(ids(index.search("walk", &Allowed::all(), 10).unwrap()), vec![2]);
        assert!(index.search("\"unbalanced", &Allowed::all(), 10).is_ok());

        index.write(&[doc(2, "person", "a person jumps", "CC-BY-4.0")], &[1]).unwrap();
        assert!(index.search("walk", &Allowed::all(), 10).unwrap().is_empty());
        assert_eq!(ids(index.search("gallops", &Allowed::all(), 10).unwrap()), vec![3]);
        let docs = index.documents().unwrap();
        assert_eq!(docs.len(), 2);
        assert_eq!(docs[0], doc(2, "person", "a person jumps", "CC-BY-4.0"));
    }

    #[test]
    fn an_index_of_another_schema_is_replaced() {
        let dir = std::env::temp_dir().join(format!("anymo-text-schema-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut old = Schema::builder();
        old.add_text_field("title", STRING | STORED);
        Index::create_in_dir(&dir, old.build()).unwrap();
        let mut index = TextIndex::open(&dir).unwrap();
        assert!(index.documents().unwrap().is_empty());
        index.write(&[doc(1, "horse", "a horse gallops", "CC0-1.0")], &[]).unwrap();
        drop(index);
        assert_eq!(TextIndex::open(&dir).unwrap().documents().unwrap().len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn snippets_mark_the_matched_words() {
        let mut index = TextIndex::in_memory();
        index.write(&[doc(1, "horse", "a horse gallops", "CC0-1.0")], &[]).unwrap();
        let highlighter = index.highlighter("gallop").unwrap();
        let captions = vec!["a horse rears".to_string(), "a horse gallops".to_string()];
        let snippet = highlighter.best(&captions).unwrap();
        assert_eq!(snippet.marked("[", "]"), "a horse [gallops]");
        let plain = highlighter.best(&["a horse rears".to_string()]).unwrap();
        assert_eq!(plain, Snippet { text: "a horse rears".into(), highlights: vec![] });
        assert!(highlighter.best(&[]).is_none());
    }
}
