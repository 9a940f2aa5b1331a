//! Reciprocal rank fusion (Cormack et al. 2009): ranked lists from different retrievers (BM25,
//! caption vectors, motion vectors) merged by `sum_i w_i / (k + rank_i)`, which needs no score
//! calibration between them.
//!
//! A retriever may be unable to rank some items at all (a clip without captions has no caption
//! vector). Plain fusion would treat that as "ranked last" and bury such clips under clips every
//! retriever can see; [`fuse_with_coverage`] treats it as unknown instead, scaling an item's
//! score by the total weight over the weight of the retrievers that cover it.

use std::collections::HashMap;

/// The customary damping constant.
pub const DEFAULT_K: f32 = 60.0;

/// Fuses ranked id lists, each with a weight; ranks start at 1. Returns ids by descending fused
/// score (ties by ascending id, so the order is deterministic).
pub fn reciprocal_rank_fusion(lists: &[(&[u64], f32)], k: f32) -> Vec<(u64, f32)> {
    let everything = |_: u64| true;
    let covered: Vec<Retrieved> =
        lists.iter().map(|&(ids, weight)| Retrieved { ids, weight, covers: &everything }).collect();
    fuse_with_coverage(&covered, k)
}

/// One retriever's ranked list, its weight, and which items it can rank at all.
pub struct Retrieved<'a> {
    /// Item ids, best first.
    pub ids: &'a [u64],
    /// The retriever's weight.
    pub weight: f32,
    /// Whether the retriever can rank an item (false: the item has no representation there).
    pub covers: &'a dyn Fn(u64) -> bool,
}

/// Reciprocal rank fusion in which an item's score is scaled by `total weight / weight of the
/// retrievers covering it` (ties by ascending id).
pub fn fuse_with_coverage(lists: &[Retrieved], k: f32) -> Vec<(u64, f32)> {
    let mut scores: HashMap<u64, f32> = HashMap::new();
    for list in lists {
        for (rank, id) in list.ids.iter().enumerate() {
            *scores.entry(*id).or_insert(0.0) += list.weight / (k + rank as f32 + 1.0);
        }
    }
    let total: f32 = lists.iter().map(|l| l.weight).sum();
    let mut fused: Vec<(u64, f32)> = scores
        .into_iter()
        .map(|(id, score)| {
            let covering: f32 = lists.iter().filter(|l| (l.covers)(id)).map(|l| l.weight).sum();
            (id, if covering > 0.0 { score * total / covering } else { score })
        })
        .collect();
    fused.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    fused
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fusion_matches_the_formula() {
        let bm25 = [7, 3, 9];
        let vectors = [3, 5];
        let fused = reciprocal_rank_fusion(&[(&bm25, 1.0), (&vectors, 2.0)], 60.0);
        let expect = |parts: &[(f32, f32)]| parts.iter().map(|(w, r)| w / (60.0 + r)).sum::<f32>();
        let by_id: HashMap<u64, f32> = fused.iter().copied().collect();
        assert!((by_id[&3] - expect(&[(1.0, 2.0), (2.0, 1.0)])).abs() < 1e-7);
        assert!((by_id[&5] - expect(&[(2.0, 2.0)])).abs() < 1e-7);
        assert!((by_id[&7] - expect(&[(1.0, 1.0)])).abs() < 1e-7);
        assert_eq!(fused.iter().map(|f| f.0).collect::<Vec<_>>(), vec![3, 5, 7, 9]);
    }

    #[test]
    fn an_item_a_retriever_cannot_see_is_not_ranked_last_there() {
        // Item 2 has no caption vector: its BM25 contribution is scaled by (1 + 1) / 1.
        let bm25 = [1, 2];
        let captions = [1, 3];
        let has_caption = |id: u64| id != 2;
        let everything = |_: u64| true;
        let fused = fuse_with_coverage(
            &[
                Retrieved { ids: &bm25, weight: 1.0, covers: &everything },
                Retrieved { ids: &captions, weight: 1.0, covers: &has_caption },
            ],
            60.0,
        );
        let by_id: HashMap<u64, f32> = fused.iter().copied().collect();
        assert!((by_id[&2] - 2.0 / 62.0).abs() < 1e-7);
        assert!((by_id[&1] - 2.0 / 61.0).abs() < 1e-7);
        assert!((by_id[&3] - 1.0 / 62.0).abs() < 1e-7);
        assert_eq!(fused.iter().map(|f| f.0).collect::<Vec<_>>(), vec![1, 2, 3]);
    }

    #[test]
    fn a_zero_weight_list_only_breaks_nothing() {
        let a = [1, 2];
        let b = [2, 1];
        let fused = reciprocal_rank_fusion(&[(&a, 1.0), (&b, 0.0)], DEFAULT_K);
        assert_eq!(fused[0].0, 1);
        assert!(reciprocal_rank_fusion(&[], DEFAULT_K).is_empty());
    }
}
