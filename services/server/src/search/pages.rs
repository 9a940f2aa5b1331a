//! Answered pages, kept by the whole request and the store's clip signature, least recently
//! used first out: a repeated query is answered without embedding or ranking again, and a page
//! is never served once the clips it was ranked among have changed.

use super::params::{SearchPage, SearchParams};
use super::signature::Signature;
use lru::LruCache;
use std::num::NonZeroUsize;
use std::sync::{Mutex, PoisonError};

/// Pages a server keeps: a page of 10 hits is a few kilobytes, so about 5 MB at most.
pub const PAGES: NonZeroUsize = NonZeroUsize::new(1_024).expect("not zero");

/// What a page is kept by: every parameter of the request (text, stored example, filters,
/// page) and the signature of the clips it was ranked among.
#[derive(Clone, Debug, Hash, PartialEq, Eq)]
pub struct PageKey {
    request: String,
    signature: Signature,
}

impl PageKey {
    /// The key of `params` asked of the clips with `signature`.
    pub fn new(params: &SearchParams, signature: Signature) -> PageKey {
        let request = serde_json::to_string(params).expect("search parameters serialise");
        PageKey { request, signature }
    }
}

/// A bounded cache of answered pages, shared by every query.
pub struct PageCache {
    pages: Mutex<LruCache<PageKey, SearchPage>>,
}

impl PageCache {
    /// A cache of at most `capacity` pages.
    pub fn new(capacity: NonZeroUsize) -> PageCache {
        PageCache { pages: Mutex::new(LruCache::new(capacity)) }
    }

    /// The page answered before for `key`.
    pub fn get(&self, key: &PageKey) -> Option<SearchPage> {
        self.pages.lock().unwrap_or_else(PoisonError::into_inner).get(key).cloned()
    }

    /// Keeps `page` for `key`, dropping the least recently used page when full.
    pub fn put(&self, key: PageKey, page: SearchPage) {
        self.pages.lock().unwrap_or_else(PoisonError::into_inner).put(key, page);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn page(candidates: usize) -> SearchPage {
        SearchPage { hits: Vec::new(), candidates }
    }

    fn params(q: &str, limit: usize) -> SearchParams {
        SearchParams { q: Some(q.into()), limit: Some(limit), ..SearchParams::default() }
    }

    #[test]
    fn a_page_is_kept_by_every_parameter_and_the_clips_signature() {
        let cache = PageCache::new(PAGES);
        cache.put(PageKey::new(&params("a horse gallops", 10), (5, 9)), page(7));
        assert_eq!(cache.get(&PageKey::new(&params("a horse gallops", 10), (5, 9))).map(|p| p.candidates), Some(7));
        // Another page size, another text, or changed clips: not this page.
        assert!(cache.get(&PageKey::new(&params("a horse gallops", 5), (5, 9))).is_none());
        assert!(cache.get(&PageKey::new(&params("a horse walks", 10), (5, 9))).is_none());
        assert!(cache.get(&PageKey::new(&params("a horse gallops", 10), (6, 10))).is_none());
        let filtered = SearchParams { licence: Some("CC0-1.0".into()), ..params("a horse gallops", 10) };
        assert!(cache.get(&PageKey::new(&filtered, (5, 9))).is_none());
    }

    #[test]
    fn the_least_recently_used_page_goes_first() {
        let cache = PageCache::new(NonZeroUsize::new(2).unwrap());
        let key = |q: &str| PageKey::new(&params(q, 10), (1, 1));
        cache.put(key("a"), page(1));
        cache.put(key("b"), page(2));
        assert!(cache.get(&key("a")).is_some());
        cache.put(key("c"), page(3));
        assert!(cache.get(&key("b")).is_none(), "b was used least recently");
        assert!(cache.get(&key("a")).is_some() && cache.get(&key("c")).is_some());
    }
}
