//! Vectors by clip id with exact nearest-neighbour search. An exact scan over unit vectors is
//! fast enough to about 100k clips (ARCHITECTURE.md); the trait leaves room for an approximate
//! index later. The scan reads int8 codes with proven error bounds first and scores in f32 only
//! the vectors that can still make the top k (`sketch`), so results equal a full f32 scan. The
//! index persists in one little-endian file, written atomically.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::sketch::{QuerySketch, Sketch};

const MAGIC: &[u8; 8] = b"ANYMOVEC";
const VERSION: u32 = 1;

/// Why an index operation failed.
#[derive(Debug, thiserror::Error)]
pub enum IndexError {
    /// A vector or query of another width than the index's.
    #[error("the index holds {expected}-dimensional vectors; this one has {got}")]
    Dimension {
        /// The index's width.
        expected: usize,
        /// The vector's width.
        got: usize,
    },
    /// A vector with a NaN or infinite component.
    #[error("vector for clip {id} has a non-finite component")]
    NotFinite {
        /// The clip.
        id: u64,
    },
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The index file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not an index this version can read.
    #[error("{path} is not a readable vector index: {reason}")]
    Corrupt {
        /// The index file.
        path: PathBuf,
        /// What was wrong.
        reason: String,
    },
}

/// A search result: a clip id and its similarity (dot product; cosine for unit vectors).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// The clip.
    pub id: u64,
    /// Similarity to the query, higher is closer.
    pub score: f32,
}

/// A vector index over clip ids.
pub trait VectorIndex {
    /// Width of the vectors.
    fn dim(&self) -> usize;
    /// Vectors held.
    fn len(&self) -> usize;
    /// Whether the index is empty.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Adds a clip's vector, replacing the one it had.
    fn upsert(&mut self, id: u64, vector: &[f32]) -> Result<(), IndexError>;
    /// Removes a clip; returns whether it was there.
    fn remove(&mut self, id: u64) -> bool;
    /// The `k` most similar vectors whose ids `keep` accepts, best first (ties by id).
    fn search(&self, query: &[f32], k: usize, keep: &dyn Fn(u64) -> bool) -> Result<Vec<Hit>, IndexError>;
}

/// Exact search by scanning every vector.
#[derive(Clone, Debug, PartialEq)]
pub struct ExactIndex {
    dim: usize,
    ids: Vec<u64>,
    vectors: Vec<f32>,
    slots: HashMap<u64, usize>,
    sketch: Sketch,
}

/// An f32 ordered for the heap (scores are finite: vectors and queries are checked).
#[derive(Clone, Copy, PartialEq)]
struct Ranked(f32, Reverse<u64>);

impl Eq for Ranked {}

impl PartialOrd for Ranked {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ranked {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0).then(self.1.cmp(&other.1))
    }
}

/// Dot product in eight independent lanes, which the compiler turns into SIMD.
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut lanes = [0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca.remainder().iter().zip(cb.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            lanes[i] += x[i] * y[i];
        }
    }
    lanes.iter().sum::<f32>() + tail
}

impl ExactIndex {
    /// An empty index of `dim`-dimensional vectors.
    pub fn new(dim: usize) -> ExactIndex {
        ExactIndex { dim, ids: Vec::new(), vectors: Vec::new(), slots: HashMap::new(), sketch: Sketch::new(dim) }
    }

    /// Whether clip `id` has a vector.
    pub fn contains(&self, id: u64) -> bool {
        self.slots.contains_key(&id)
    }

    /// Clip `id`'s vector.
    pub fn get(&self, id: u64) -> Option<&[f32]> {
        self.slots.get(&id).map(|&slot| &self.vectors[slot * self.dim..(slot + 1) * self.dim])
    }

    /// The clip ids held, in storage order.
    pub fn ids(&self) -> impl Iterator<Item = u64> + '_ {
        self.ids.iter().copied()
    }

    fn check(&self, id: u64, vector: &[f32]) -> Result<(), IndexError> {
        if vector.len() != self.dim {
            return Err(IndexError::Dimension { expected: self.dim, got: vector.len() });
        }
        if vector.iter().any(|v| !v.is_finite()) {
            return Err(IndexError::NotFinite { id });
        }
        Ok(())
    }

    /// Writes the index to `path` (through a temporary file renamed into place, so a crash
    /// leaves the previous file).
    pub fn save(&self, path: &Path) -> Result<(), IndexError> {
        let io = |source| IndexError::Io { path: path.to_path_buf(), source };
        let mut bytes = Vec::with_capacity(24 + self.ids.len() * (8 + 4 * self.dim));
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&VERSION.to_le_bytes());
        bytes.extend_from_slice(&(self.dim as u32).to_le_bytes());
        bytes.extend_from_slice(&(self.ids.len() as u64).to_le_bytes());
        self.ids.iter().for_each(|id| bytes.extend_from_slice(&id.to_le_bytes()));
        self.vectors.iter().for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
        let tmp = path.with_extension("tmp");
        let mut file = std::fs::File::create(&tmp).map_err(io)?;
        file.write_all(&bytes).map_err(io)?;
        file.sync_all().map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// Reads an index written by [`ExactIndex::save`].
    pub fn load(path: &Path) -> Result<ExactIndex, IndexError> {
        let bytes = std::fs::read(path).map_err(|source| IndexError::Io { path: path.to_path_buf(), source })?;
        let corrupt = |reason: String| IndexError::Corrupt { path: path.to_path_buf(), reason };
        if bytes.len() < 24 || &bytes[..8] != MAGIC {
            return Err(corrupt("it does not start with the anymo vector header".into()));
        }
        let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
        if word(8) != VERSION {
            return Err(corrupt(format!("version {} (this anymo reads {VERSION})", word(8))));
        }
        let dim = word(12) as usize;
        let count = u64::from_le_bytes(bytes[16..24].try_into().expect("8 bytes")) as usize;
        let expected = count.checked_mul(8 + 4 * dim).and_then(|n| n.checked_add(24));
        if expected != Some(bytes.len()) {
            return Err(corrupt(format!(
                "{count} vectors of {dim} need {expected:?} bytes; the file has {}",
                bytes.len()
            )));
        }
        let ids: Vec<u64> = bytes[24..24 + 8 * count]
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        let vectors: Vec<f32> = bytes[24 + 8 * count..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        let slots: HashMap<u64, usize> = ids.iter().enumerate().map(|(i, &id)| (id, i)).collect();
        if slots.len() != ids.len() {
            return Err(corrupt("a clip id appears twice".into()));
        }
        let mut sketch = Sketch::new(dim);
        vectors.chunks_exact(dim.max(1)).take(ids.len()).for_each(|v| sketch.push(v));
        Ok(ExactIndex { dim, ids, vectors, slots, sketch })
    }
}

/// Pass 1 of a search: bounds from the int8 codes. The k-th best lower bound so far is a score
/// the true k-th best reaches, and it only rises, so a vector whose upper bound falls short of it
/// cannot be in the top k. Yields the candidates' slots with their upper bounds, and the final
/// threshold. A [`pulp::WithSimd`] operation, so the scan is compiled for AVX2 and chosen at run
/// time where the CPU has it (caption vectors at 50k clips: p50 2.96 ms with SSE2 only, 1.19 ms
/// with this; `cargo bench -p anymo-services --bench search`).
struct FirstPass<'a> {
    index: &'a ExactIndex,
    query: &'a QuerySketch,
    k: usize,
    keep: &'a dyn Fn(u64) -> bool,
}

impl pulp::WithSimd for FirstPass<'_> {
    type Output = (Vec<(usize, f32)>, f32);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        let FirstPass { index, query, k, keep } = self;
        let mut lows: BinaryHeap<Reverse<Ranked>> = BinaryHeap::with_capacity(k + 1);
        let mut threshold = f32::NEG_INFINITY;
        let mut bounds: Vec<(usize, f32)> = Vec::new();
        for (slot, &id) in index.ids.iter().enumerate() {
            if !keep(id) {
                continue;
            }
            let (low, high) = index.sketch.bounds(slot, query);
            if high < threshold {
                continue;
            }
            bounds.push((slot, high));
            lows.push(Reverse(Ranked(low, Reverse(0))));
            if lows.len() > k {
                lows.pop();
            }
            if lows.len() == k {
                threshold = lows.peek().map_or(threshold, |r| r.0.0);
            }
        }
        (bounds, threshold)
    }
}

impl VectorIndex for ExactIndex {
    fn dim(&self) -> usize {
        self.dim
    }

    fn len(&self) -> usize {
        self.ids.len()
    }

    fn upsert(&mut self, id: u64, vector: &[f32]) -> Result<(), IndexError> {
        self.check(id, vector)?;
        match self.slots.get(&id) {
            Some(&slot) => {
                self.vectors[slot * self.dim..(slot + 1) * self.dim].copy_from_slice(vector);
                self.sketch.set(slot, vector);
            }
            None => {
                self.slots.insert(id, self.ids.len());
                self.ids.push(id);
                self.vectors.extend_from_slice(vector);
                self.sketch.push(vector);
            }
        }
        Ok(())
    }

    fn remove(&mut self, id: u64) -> bool {
        let Some(slot) = self.slots.remove(&id) else { return false };
        let last = self.ids.len() - 1;
        if slot != last {
            self.ids.swap(slot, last);
            let (d, moved) = (self.dim, self.ids[slot]);
            self.vectors.copy_within(last * d..(last + 1) * d, slot * d);
            self.slots.insert(moved, slot);
        }
        self.ids.pop();
        self.vectors.truncate(last * self.dim);
        self.sketch.swap_remove(slot);
        true
    }

    fn search(&self, query: &[f32], k: usize, keep: &dyn Fn(u64) -> bool) -> Result<Vec<Hit>, IndexError> {
        self.check(0, query)?;
        if k == 0 {
            return Ok(Vec::new());
        }
        let q = self.sketch.query(query);
        let (bounds, threshold) = pulp::Arch::new().dispatch(FirstPass { index: self, query: &q, k, keep });
        // Pass 2: exact scores of the vectors that can still make it.
        let mut best: BinaryHeap<Reverse<Ranked>> = BinaryHeap::with_capacity(k + 1);
        for &(slot, high) in &bounds {
            if high < threshold {
                continue;
            }
            let score = dot(query, &self.vectors[slot * self.dim..(slot + 1) * self.dim]);
            let ranked = Ranked(score, Reverse(self.ids[slot]));
            if best.len() < k {
                best.push(Reverse(ranked));
            } else if best.peek().is_some_and(|worst| ranked > worst.0) {
                best.pop();
                best.push(Reverse(ranked));
            }
        }
        let mut hits: Vec<Ranked> = best.into_iter().map(|r| r.0).collect();
        hits.sort_by(|a, b| b.cmp(a));
        Ok(hits.into_iter().map(|r| Hit { id: r.1.0, score: r.0 }).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(vectors: &[(u64, Vec<f32>)], query: &[f32], k: usize) -> Vec<u64> {
        let mut all: Vec<(f32, u64)> =
            vectors.iter().map(|(id, v)| (v.iter().zip(query).map(|(a, b)| a * b).sum::<f32>(), *id)).collect();
        all.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        all.into_iter().take(k).map(|x| x.1).collect()
    }

    proptest! {
        #[test]
        fn search_equals_a_full_sort(
            vectors in proptest::collection::vec(proptest::collection::vec(-4i8..4, 11), 0..40),
            query in proptest::collection::vec(-4i8..4, 11),
            k in 0usize..12,
        ) {
            // Small integers make every dot product exact, so ties are real ties.
            let vectors: Vec<(u64, Vec<f32>)> =
                vectors.into_iter().enumerate().map(|(i, v)| (i as u64 * 3, v.into_iter().map(f32::from).collect())).collect();
            let query: Vec<f32> = query.into_iter().map(f32::from).collect();
            let mut index = ExactIndex::new(11);
            for (id, v) in &vectors {
                index.upsert(*id, v).unwrap();
            }
            let got: Vec<u64> = index.search(&query, k, &|_| true).unwrap().iter().map(|h| h.id).collect();
            prop_assert_eq!(got, brute(&vectors, &query, k));
        }
    }

    proptest! {
        #[test]
        fn search_of_real_valued_vectors_equals_a_full_f32_scan(
            vectors in proptest::collection::vec(proptest::collection::vec(-1.0f32..1.0, 24), 0..120),
            query in proptest::collection::vec(-1.0f32..1.0, 24),
            duplicates in 0usize..6,
            k in 1usize..15,
        ) {
            // Near-duplicates (as in a library with re-exports) make the bounds overlap most.
            let mut vectors: Vec<(u64, Vec<f32>)> =
                vectors.into_iter().enumerate().map(|(i, v)| (i as u64, v)).collect();
            for d in 0..duplicates.min(vectors.len()) {
                let mut twin = vectors[d].1.clone();
                twin[0] += 1e-6;
                vectors.push((1000 + d as u64, twin));
            }
            let mut index = ExactIndex::new(24);
            for (id, v) in &vectors {
                index.upsert(*id, v).unwrap();
            }
            let mut all: Vec<(f32, u64)> = vectors.iter().map(|(id, v)| (dot(&query, v), *id)).collect();
            all.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            let expected: Vec<u64> = all.into_iter().take(k).map(|x| x.1).collect();
            let got: Vec<u64> = index.search(&query, k, &|_| true).unwrap().iter().map(|h| h.id).collect();
            prop_assert_eq!(got, expected);
        }
    }

    #[test]
    fn updates_removals_filters_and_persistence() {
        let mut index = ExactIndex::new(2);
        index.upsert(1, &[1.0, 0.0]).unwrap();
        index.upsert(2, &[0.0, 1.0]).unwrap();
        index.upsert(3, &[0.6, 0.8]).unwrap();
        index.upsert(1, &[-1.0, 0.0]).unwrap();
        assert_eq!(index.len(), 3);
        assert_eq!(index.get(1), Some(&[-1.0, 0.0][..]));
        assert_eq!(index.get(7), None);
        let ids = |hits: Vec<Hit>| hits.into_iter().map(|h| h.id).collect::<Vec<_>>();
        assert_eq!(ids(index.search(&[1.0, 0.0], 3, &|_| true).unwrap()), vec![3, 2, 1]);
        assert_eq!(ids(index.search(&[1.0, 0.0], 3, &|id| id != 3).unwrap()), vec![2, 1]);
        assert!(index.remove(2));
        assert!(!index.remove(2));
        assert_eq!(ids(index.search(&[0.0, 1.0], 5, &|_| true).unwrap()), vec![3, 1]);

        let dir = std::env::temp_dir().join(format!("anymo-vectors-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("motion.vec");
        index.save(&path).unwrap();
        assert_eq!(ExactIndex::load(&path).unwrap(), index);

        let mut bytes = std::fs::read(&path).unwrap();
        bytes.pop();
        std::fs::write(&path, &bytes).unwrap();
        assert!(matches!(ExactIndex::load(&path), Err(IndexError::Corrupt { .. })));
        std::fs::write(&path, b"not an index at all, clearly").unwrap();
        let message = ExactIndex::load(&path).unwrap_err().to_string();
        assert!(message.contains("anymo vector header"), "{message}");

        assert!(matches!(index.upsert(9, &[1.0]), Err(IndexError::Dimension { expected: 2, got: 1 })));
        assert!(matches!(index.upsert(9, &[f32::NAN, 0.0]), Err(IndexError::NotFinite { id: 9 })));
        assert!(matches!(index.search(&[1.0, 2.0, 3.0], 1, &|_| true), Err(IndexError::Dimension { .. })));
    }
}
