//! Reciprocal rank fusion (Cormack et al. 2009): ranked lists from different retrievers (BM25,
//! caption vectors, motion vectors) merged by `sum_i w_i / (k + rank_i)`, which needs no score
//! calibration between them.

use std::collections::HashMap;

/// The customary damping constant.
pub const DEFAULT_K: f32 = 60.0;

/// Fuses ranked id lists, each with a weight; ranks start at 1. Returns ids by descending fused
/// score (ties by ascending id, so the order is deterministic).
pub fn reciprocal_rank_fusion(lists: &[(&[u64], f32)], k: f32) -> Vec<(u64, f32)> {
    let mut scores: HashMap<u64, f32> = HashMap::new();
    for (list, weight) in lists {
        for (rank, id) in list.iter().enumerate() {
            *scores.entry(*id).or_insert(0.0) += weight / (k + rank as f32 + 1.0);
        }
    }
    let mut fused: Vec<(u64, f32)> = scores.into_iter().collect();
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
    fn a_zero_weight_list_only_breaks_nothing() {
        let a = [1, 2];
        let b = [2, 1];
        let fused = reciprocal_rank_fusion(&[(&a, 1.0), (&b, 0.0)], DEFAULT_K);
        assert_eq!(fused[0].0, 1);
        assert!(reciprocal_rank_fusion(&[], DEFAULT_K).is_empty());
    }
}
