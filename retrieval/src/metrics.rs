//! Retrieval figures (EVAL.md): recall at k, mean reciprocal rank and median rank, from the rank
//! of the first relevant result of each query.

use serde::Serialize;

/// Recall at 1, 5 and 10, mean reciprocal rank and the median rank over a set of queries.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RankSummary {
    /// Queries counted.
    pub queries: usize,
    /// Share of queries with a relevant result first.
    pub r1: f32,
    /// ... within the first 5.
    pub r5: f32,
    /// ... within the first 10.
    pub r10: f32,
    /// Mean of 1 / rank of the first relevant result.
    pub mrr: f32,
    /// Median rank of the first relevant result (1 is best).
    pub median_rank: f32,
}

impl RankSummary {
    /// Summarises 1-based ranks, one per query.
    pub fn of(ranks: &[usize]) -> RankSummary {
        let n = ranks.len();
        let within = |k: usize| ranks.iter().filter(|&&r| r <= k).count() as f32 / n.max(1) as f32;
        let mut sorted = ranks.to_vec();
        sorted.sort_unstable();
        let median_rank = match n {
            0 => 0.0,
            _ if n % 2 == 1 => sorted[n / 2] as f32,
            _ => (sorted[n / 2 - 1] + sorted[n / 2]) as f32 / 2.0,
        };
        let mrr = ranks.iter().map(|&r| 1.0 / r.max(1) as f32).sum::<f32>() / n.max(1) as f32;
        RankSummary { queries: n, r1: within(1), r5: within(5), r10: within(10), mrr, median_rank }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recall_and_median_by_hand() {
        let s = RankSummary::of(&[1, 3, 7, 12]);
        let mrr = (1.0 + 1.0 / 3.0 + 1.0 / 7.0 + 1.0 / 12.0) / 4.0;
        assert_eq!(s, RankSummary { queries: 4, r1: 0.25, r5: 0.5, r10: 0.75, mrr, median_rank: 5.0 });
        assert_eq!(RankSummary::of(&[2, 1, 9]).median_rank, 2.0);
        assert_eq!(RankSummary::of(&[]).queries, 0);
    }
}
