//! Both runs of a claim's pair scored on the variant run's pixel classes (SPEC.md §21.5):
//! where two of the variant's stage-1 views generated one surface point (*contested*) and
//! where at most one did (*uncontested*). The reference run is scored on the variant's
//! pixels, so a difference between the two runs on contested pixels, less their difference
//! on uncontested ones, is what conflicts do, with everything global to the runs removed.

use crate::error::{Error, Result};
use crate::eval::{DepthRender, consistency_errors};
use crate::gaussian::Gaussians;
use crate::pipeline::Inputs;
use crate::pipeline::evaluate::{CLASS_CONTESTED, CLASS_UNCONTESTED, ClassSums, ScoredView};
use crate::raster::{Outputs, RenderOptions, render};

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
/// per pixel, the views in evaluation order): each class's PSNR, SSIM and gradient sums,
/// and its multi-view consistency against the nearest other evaluation view
/// ([`neighbours`], [`crate::eval::consistency_errors`]).
pub fn score_pair(
    inputs: &Inputs,
    reference: &Gaussians,
    variant: &Gaussians,
    classes: &[u8],
) -> Result<Vec<PairView>> {
    let data = &inputs.data;
    let views: Vec<&crate::dataset::View> =
        inputs.evaluation.iter().map(|&i| &data.views[i]).collect();
    let pixels: usize = views.iter().map(|v| v.image.width * v.image.height).sum();
    if classes.len() != pixels {
        return Err(Error::invalid(format!(
            "{} pixel classes for {pixels} evaluation pixels",
            classes.len()
        )));
    }
    let opts = RenderOptions {
        background: inputs.background,
        outputs: Outputs {
            rgb: true,
            alpha: true,
            expected_depth: true,
            ..Outputs::RGB
        },
        ..RenderOptions::default()
    };
    // Both scenes at every view: the scored render, with its alpha and expected depth.
    let mut seen: [Vec<Seen>; 2] = [Vec::new(), Vec::new()];
    for (scene, out) in [reference, variant].into_iter().zip(&mut seen) {
        for v in &views {
            let r = render(scene, &v.camera, &opts)?;
            let (w, h) = (r.width, r.height);
            if v.image.data.len() != w * h * 3 {
                return Err(Error::invalid(format!(
                    "evaluation view '{}': an image of {} values for a {w}×{h} camera",
                    v.camera.name,
                    v.image.data.len()
                )));
            }
            let scored = ScoredView::of_render(r.rgb.expect("rgb"), &v.image.data, w, h);
            out.push(Seen {
                scored,
                alpha: r.alpha.expect("alpha"),
                depth: r.expected_depth.expect("expected depth"),
            });
        }
    }
    let neighbour = neighbours(&views.iter().map(|v| &v.camera).collect::<Vec<_>>());
    let mut at = 0;
    let mut out = Vec::with_capacity(views.len());
    for (k, v) in views.iter().enumerate() {
        let n = v.image.width * v.image.height;
        let class = &classes[at..at + n];
        at += n;
        let mut errors: [Option<Vec<f64>>; 2] = [None, None];
        if let Some(from) = neighbour[k] {
            for (e, side) in errors.iter_mut().zip(&seen) {
                *e = Some(consistency_errors(
                    side[from].at(&views[from].camera),
                    side[k].at(&v.camera),
                )?);
            }
        }
        let mut view = PairView {
            view: v.camera.name.clone(),
            contested: Default::default(),
            uncontested: Default::default(),
        };
        for s in view.contested.iter_mut().chain(&mut view.uncontested) {
            s.consistency = Some(Default::default());
        }
        for (p, &c) in class.iter().enumerate() {
            let sums = match c {
                CLASS_CONTESTED => &mut view.contested,
                CLASS_UNCONTESTED => &mut view.uncontested,
                _ => continue,
            };
            for ((s, side), e) in sums.iter_mut().zip(&seen).zip(&errors) {
                s.add(&side[k].scored, p);
                s.add_consistency(e.as_ref().map_or(f64::NAN, |e| e[p]));
            }
        }
        out.push(view);
    }
    Ok(out)
}

/// A scene's scored render at a view, with the alpha and expected depth that multi-view
/// consistency warps by.
struct Seen<'a> {
    scored: ScoredView<'a>,
    alpha: Vec<f32>,
    depth: Vec<f32>,
}

impl Seen<'_> {
    fn at<'b>(&'b self, camera: &'b crate::camera::Camera) -> DepthRender<'b> {
        DepthRender {
            camera,
            rgb: &self.scored.rgb,
            alpha: &self.alpha,
            depth: &self.depth,
        }
    }
}

/// Each camera's nearest other camera by centre (ties: the earlier), whose render
/// multi-view consistency warps into it; none for a lone camera.
pub fn neighbours(cameras: &[&crate::camera::Camera]) -> Vec<Option<usize>> {
    (0..cameras.len())
        .map(|k| {
            (0..cameras.len())
                .filter(|&l| l != k)
                .map(|l| (cameras[l].center.distance_squared(cameras[k].center), l))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
                .map(|(_, l)| l)
        })
        .collect()
}

/// The folder of an audit's contact sheets, `sheets/<generator>/<variant>/seed-<s>.png`.
pub const SHEETS_DIR: &str = "sheets";

/// Where the contact sheet of a run's pair lies, relative to the audit's folder.
pub fn sheet_path(generator: &str, variant: &str, seed: u32) -> std::path::PathBuf {
    std::path::Path::new(SHEETS_DIR)
        .join(generator)
        .join(variant)
        .join(format!("seed-{seed}.png"))
}

/// Pixels of a contact sheet panel per pixel of the view (nearest neighbour).
pub const SHEET_SCALE: usize = 4;

/// Gap between the panels of a contact sheet, in sheet pixels (white).
const SHEET_GAP: usize = 4;

/// Factor of the absolute difference in a contact sheet's last panel.
pub const SHEET_DIFFERENCE_GAIN: f32 = 4.0;

/// Brightness kept outside the contested pixels in a contact sheet's crop.
const SHEET_DIM: f32 = 0.35;

/// A contact sheet of a pair on its most contested evaluation view (`None` when no view has
/// a contested pixel): four panels side by side — truth, the reference's render, the
/// variant's, and `SHEET_DIFFERENCE_GAIN · |reference − variant|` — each the bounding box of
/// the view's contested pixels, the other pixels of the box dimmed to `SHEET_DIM`, scaled
/// `SHEET_SCALE`× by nearest neighbour (SPEC.md §21.7).
pub fn contact_sheet(
    inputs: &Inputs,
    reference: &Gaussians,
    variant: &Gaussians,
    classes: &[u8],
) -> Result<Option<crate::io::image::ImageF32>> {
    let data = &inputs.data;
    let mut best: Option<(usize, usize, usize)> = None; // (contested, view, offset)
    let mut at = 0;
    for &i in &inputs.evaluation {
        let v = &data.views[i];
        let n = v.image.width * v.image.height;
        let Some(class) = classes.get(at..at + n) else {
            return Err(Error::invalid(format!(
                "{} pixel classes for the evaluation views",
                classes.len()
            )));
        };
        let c = class.iter().filter(|&&c| c == CLASS_CONTESTED).count();
        if c > best.map_or(0, |b| b.0) {
            best = Some((c, i, at));
        }
        at += n;
    }
    let Some((_, i, at)) = best else {
        return Ok(None);
    };
    let v = &data.views[i];
    let (w, h) = (v.image.width, v.image.height);
    let class = &classes[at..at + w * h];
    let contested = |x: usize, y: usize| class[y * w + x] == CLASS_CONTESTED;
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
    for y in 0..h {
        for x in (0..w).filter(|&x| contested(x, y)) {
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
        }
    }
    let opts = RenderOptions {
        background: inputs.background,
        ..RenderOptions::default()
    };
    let render = |g: &Gaussians| -> Result<Vec<f32>> {
        Ok(crate::raster::render(g, &v.camera, &opts)?
            .rgb
            .expect("rgb"))
    };
    let (a, b) = (render(reference)?, render(variant)?);
    let panel = |x: usize, y: usize, k: usize, c: usize| -> f32 {
        let p = (y * w + x) * 3 + c;
        let value = match k {
            0 => v.image.data[p],
            1 => a[p],
            2 => b[p],
            _ => SHEET_DIFFERENCE_GAIN * (a[p].clamp(0.0, 1.0) - b[p].clamp(0.0, 1.0)).abs(),
        };
        let dim = if contested(x, y) { 1.0 } else { SHEET_DIM };
        value.clamp(0.0, 1.0) * dim
    };
    let (cw, ch) = ((x1 - x0 + 1) * SHEET_SCALE, (y1 - y0 + 1) * SHEET_SCALE);
    let width = 4 * cw + 3 * SHEET_GAP;
    let mut img = crate::io::image::ImageF32 {
        width,
        height: ch,
        channels: 3,
        data: vec![1.0; width * ch * 3],
    };
    for k in 0..4 {
        for sy in 0..ch {
            for sx in 0..cw {
                let (x, y) = (x0 + sx / SHEET_SCALE, y0 + sy / SHEET_SCALE);
                let o = (sy * width + k * (cw + SHEET_GAP) + sx) * 3;
                for c in 0..3 {
                    img.data[o + c] = panel(x, y, k, c);
                }
            }
        }
    }
    Ok(Some(img))
}
