//! The captions a generator was trained on, kept with its weights as sentence embeddings, so a
//! prompt can be read as the caption nearest to it.
//!
//! Why: the generator learns a text condition from a few hundred distinct captions ("a person
//! walks in an active manner"). A prompt worded like none of them ("somebody strolls ahead")
//! embeds far from every point it trained on, and the condition it gets there means little:
//! measured with `anymo eval prompts`, 23.5% of such prompts' samples pass their action's checks
//! on human rigs where the same actions asked in the captions' own words pass 66.9%
//! (docs/measurements/generation.md). Sentence embeddings often find the caption a paraphrase
//! means (by caption vectors alone, search ranks a relevant clip first for 58% of its paraphrase
//! benchmark's test half), so the generator is handed that caption, a point it knows. A prompt already as close to some caption as most captions
//! are to their nearest other one is read as it is: it lies among the points the generator
//! trained on (a training caption, or a caption of the corpus's own wording the training clips
//! lack, such as "a horse gallops", whose nearest training caption "a horse jumps while
//! galloping" asks for more).

use candle_core::{Device, Result, Tensor};

/// The name of the anchors' tensor in a generator's weights file (`captions x 384`).
pub const ANCHORS_TENSOR: &str = "anchors/captions";

/// The name of the tensor holding [`CaptionAnchors::within`] (one value).
pub const WITHIN_TENSOR: &str = "anchors/within";

/// [`CaptionAnchors::within`] is this quantile of the captions' cosines to their nearest other
/// caption: nine in ten captions are at least that close to another.
pub const WITHIN_QUANTILE: f32 = 0.1;

/// Unit sentence embeddings of distinct captions, one row each.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptionAnchors {
    width: usize,
    rows: Vec<f32>,
    within: f32,
}

impl CaptionAnchors {
    /// Anchors from caption embeddings; duplicates (the same caption on several clips) are kept
    /// once and every row is scaled to unit length. `None` when there is no row, or a row is
    /// empty, of another width than the first, or zero.
    pub fn new<'a>(embeddings: impl IntoIterator<Item = &'a [f32]>) -> Option<CaptionAnchors> {
        let mut unit: Vec<Vec<f32>> = Vec::new();
        for row in embeddings {
            let length = norm(row);
            if row.is_empty() || unit.first().is_some_and(|f| f.len() != row.len()) || length <= 0.0 {
                return None;
            }
            let row: Vec<f32> = row.iter().map(|v| v / length).collect();
            if !unit.contains(&row) {
                unit.push(row);
            }
        }
        let width = unit.first()?.len();
        let within = within(&unit);
        Some(CaptionAnchors { width, rows: unit.concat(), within })
    }

    /// The anchors stored in a weights file's tensors (see [`ANCHORS_TENSOR`] and
    /// [`WITHIN_TENSOR`]).
    pub fn from_tensors(captions: &Tensor, within: &Tensor) -> Result<CaptionAnchors> {
        let rows: Vec<Vec<f32>> = captions.to_dtype(candle_core::DType::F32)?.to_vec2()?;
        let mut anchors = CaptionAnchors::new(rows.iter().map(Vec::as_slice))
            .ok_or_else(|| candle_core::Error::Msg(format!("{ANCHORS_TENSOR} holds no usable caption embedding")))?;
        anchors.within =
            within.to_dtype(candle_core::DType::F32)?.flatten_all()?.to_vec1()?.first().copied().unwrap_or(1.0);
        Ok(anchors)
    }

    /// The anchors as the two tensors a weights file stores: the captions and
    /// [`CaptionAnchors::within`].
    pub fn to_tensors(&self) -> Result<[(&'static str, Tensor); 2]> {
        Ok([
            (ANCHORS_TENSOR, Tensor::from_vec(self.rows.clone(), (self.len(), self.width), &Device::Cpu)?),
            (WITHIN_TENSOR, Tensor::new(&[self.within], &Device::Cpu)?),
        ])
    }

    /// The cosine to its nearest caption at or above which a prompt is read as it is: the
    /// [`WITHIN_QUANTILE`] of the captions' cosines to their nearest other caption (1 for a
    /// single caption).
    pub fn within(&self) -> f32 {
        self.within
    }

    /// Distinct captions held.
    pub fn len(&self) -> usize {
        self.rows.len() / self.width
    }

    /// Whether no caption is held (never: [`CaptionAnchors::new`] refuses none).
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// How the generator reads a unit sentence embedding: as the caption nearest to it by cosine
    /// (the first of equals), unless it is at least [`CaptionAnchors::within`] of one, or has
    /// another width or no length (the unconditional prompt stays zero): then as it is.
    pub fn read(&self, text: &[f32]) -> Vec<f32> {
        if text.len() != self.width || norm(text) <= 0.0 {
            return text.to_vec();
        }
        let (cosine, nearest) = nearest(&self.rows, self.width, text, None);
        if cosine >= self.within {
            return text.to_vec();
        }
        self.rows[nearest * self.width..(nearest + 1) * self.width].to_vec()
    }
}

/// The highest cosine of `text` to a row of `rows` (`width` wide), other than row `skip`, and
/// that row.
fn nearest(rows: &[f32], width: usize, text: &[f32], skip: Option<usize>) -> (f32, usize) {
    let mut best = (f32::NEG_INFINITY, 0);
    for (i, row) in rows.chunks(width).enumerate().filter(|(i, _)| Some(*i) != skip) {
        let cosine: f32 = row.iter().zip(text).map(|(a, b)| a * b).sum();
        if cosine > best.0 {
            best = (cosine, i);
        }
    }
    best
}

/// The [`WITHIN_QUANTILE`] of the unit rows' cosines to their nearest other row (1 for one row).
fn within(unit: &[Vec<f32>]) -> f32 {
    if unit.len() < 2 {
        return 1.0;
    }
    let flat = unit.concat();
    let width = unit[0].len();
    let mut closest: Vec<f32> = unit.iter().enumerate().map(|(i, row)| nearest(&flat, width, row, Some(i)).0).collect();
    closest.sort_by(f32::total_cmp);
    closest[((closest.len() - 1) as f32 * WITHIN_QUANTILE).round() as usize]
}

fn norm(row: &[f32]) -> f32 {
    row.iter().map(|v| v * v).sum::<f32>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit rows at the given angles (degrees) in the XY plane, and one along Z.
    fn anchors() -> CaptionAnchors {
        let at = |deg: f32| [deg.to_radians().cos(), deg.to_radians().sin(), 0.0];
        let rows = [at(0.0), at(10.0), at(90.0), [0.0, 0.0, 2.0], at(0.0)];
        CaptionAnchors::new(rows.iter().map(|r| r.as_slice())).unwrap()
    }

    #[test]
    fn a_prompt_far_from_every_caption_reads_as_the_nearest_one() {
        let anchors = anchors();
        assert_eq!(anchors.len(), 4, "the repeated caption is kept once");
        // Nearest-other cosines: cos 10 deg twice, cos 80 deg and 0; the 0.1 quantile of the
        // four (rank 0.3, rounded to 0) is the lowest.
        assert!((anchors.within() - 0.0).abs() < 1e-6, "{}", anchors.within());
        let tight = CaptionAnchors::new([[1.0f32, 0.0].as_slice(), &[0.6, 0.8]]).unwrap();
        assert!((tight.within() - 0.6).abs() < 1e-6, "{}", tight.within());
        // 60 deg below the first caption (cosine 0.5 < 0.6) and further from the second.
        let far = [60f32.to_radians().cos(), -(60f32.to_radians().sin())];
        assert_eq!(tight.read(&far), [1.0, 0.0]);
        // 10 deg from the first: cosine 0.98, among the captions: read as it is.
        let near = [10f32.to_radians().cos(), 10f32.to_radians().sin()];
        assert_eq!(tight.read(&near), near);
        assert_eq!(tight.read(&[0.0; 2]), [0.0; 2], "the unconditional prompt stays zero");
        assert_eq!(tight.read(&[1.0, 0.0, 0.0]), [1.0, 0.0, 0.0], "another width is left alone");
    }

    #[test]
    fn anchors_round_trip_through_their_tensors_and_refuse_bad_rows() {
        let anchors = anchors();
        let [(_, captions), (_, within)] = anchors.to_tensors().unwrap();
        assert_eq!(CaptionAnchors::from_tensors(&captions, &within).unwrap(), anchors);
        assert_eq!(CaptionAnchors::new([[0.0f32, 3.0].as_slice()]).unwrap().within(), 1.0, "one caption");
        assert!(CaptionAnchors::new(std::iter::empty()).is_none());
        assert!(CaptionAnchors::new([[1.0f32, 0.0].as_slice(), &[1.0]]).is_none(), "widths differ");
        assert!(CaptionAnchors::new([[0.0f32, 0.0].as_slice()]).is_none(), "a zero row");
    }
}
