//! Both runs of a claim's pair scored on the variant run's pixel classes (SPEC.md §21.5):
//! where two of the variant's stage-1 views generated one surface point (*contested*) and
//! where at most one did (*uncontested*). The reference run is scored on the variant's
//! pixels, so a difference between the two runs on contested pixels, less their difference
//! on uncontested ones, is what conflicts do, with everything global to the runs removed.

use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::pipeline::Inputs;
use crate::pipeline::evaluate::{CLASS_CONTESTED, CLASS_UNCONTESTED, ClassSums, ScoredView};
use crate::raster::RenderOptions;

/// A run paired with its seed's `full` run (same generator, same numerics revision): both
/// final scenes scored on this run's pixel classes.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pair {
    /// The reference run's variant and its final scene's digest (what the sums are of).
    pub reference: String,
    pub reference_scene: String,
    pub views: Vec<PairView>,
}

/// One evaluation view of a pair: the reference's and the variant's sums (in that order) on
/// the variant's contested and uncontested pixels.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairView {
    pub view: String,
    pub contested: [ClassSums; 2],
    pub uncontested: [ClassSums; 2],
}

/// Score `reference` and `variant` at every evaluation view of `inputs` on `classes`, the
/// variant run's class of each evaluation pixel ([`super::jobs::CLASSES_FILE`]: one byte
/// per pixel, the views in evaluation order).
pub fn score_pair(
    inputs: &Inputs,
    reference: &Gaussians,
    variant: &Gaussians,
    classes: &[u8],
) -> Result<Vec<PairView>> {
    let data = &inputs.data;
    let pixels: usize = inputs
        .evaluation
        .iter()
        .map(|&i| data.views[i].image.width * data.views[i].image.height)
        .sum();
    if classes.len() != pixels {
        return Err(Error::invalid(format!(
            "{} pixel classes for {pixels} evaluation pixels",
            classes.len()
        )));
    }
    let opts = RenderOptions {
        background: inputs.background,
        ..RenderOptions::default()
    };
    let mut at = 0;
    let mut out = Vec::with_capacity(inputs.evaluation.len());
    for &i in &inputs.evaluation {
        let v = &data.views[i];
        let n = v.image.width * v.image.height;
        let class = &classes[at..at + n];
        at += n;
        let scored = [
            ScoredView::new(reference, v, &opts)?,
            ScoredView::new(variant, v, &opts)?,
        ];
        let mut view = PairView {
            view: v.camera.name.clone(),
            contested: Default::default(),
            uncontested: Default::default(),
        };
        for (p, &c) in class.iter().enumerate() {
            let sums = match c {
                CLASS_CONTESTED => &mut view.contested,
                CLASS_UNCONTESTED => &mut view.uncontested,
                _ => continue,
            };
            for (s, run) in sums.iter_mut().zip(&scored) {
                s.add(run, p);
            }
        }
        out.push(view);
    }
    Ok(out)
}
