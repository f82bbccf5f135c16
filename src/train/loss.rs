//! Image losses and their gradients with respect to the rendered images (SPEC.md §13).
//!
//! One weighted sum covers INRIA's `0.8·L1 + 0.2·(1 − SSIM)`, plain L1 / L2, and the
//! paper's masked loss (Eq. 7):
//!
//! `L = λ1‖M⊙(Ip−Igt)‖₁ + λ2·(1 − SSIM(M⊙Ip, M⊙Igt)) + λ3‖M⊙(Dp−Dgt)‖₁`
//!
//! with a per-pixel weight map `M` (one value per pixel, shared by the channels). The paper
//! writes `+λ2·SSIM`; the trained quantity is the D-SSIM term (INRIA `train.py` minimises `1 − ssim`). Norms are
//! means, as INRIA's `l1_loss`: the RGB terms over all `W·H·3` values, the depth term over
//! the pixels whose target depth is finite and positive (Mitsuba writes 0 where a ray
//! misses). Sums are accumulated in f64 in pixel order, so the value does not depend on
//! the thread count.

use crate::error::{Error, Result};
use crate::train::ssim::ssim;

/// Weights of the loss terms.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LossWeights {
    /// Mean absolute RGB difference.
    pub l1: f32,
    /// Mean squared RGB difference.
    pub l2: f32,
    /// `1 − SSIM` on RGB.
    pub dssim: f32,
    /// Mean absolute depth difference over valid target pixels.
    pub depth: f32,
}

impl LossWeights {
    /// Every term off: the base the others are written over.
    const ZERO: LossWeights = LossWeights {
        l1: 0.0,
        l2: 0.0,
        dssim: 0.0,
        depth: 0.0,
    };
    /// INRIA 3DGS: `(1 − 0.2)·L1 + 0.2·D-SSIM` (`lambda_dssim = 0.2`).
    pub const INRIA: LossWeights = LossWeights {
        l1: 0.8,
        dssim: 0.2,
        ..Self::ZERO
    };
    /// The paper's Eq. 7 with λ1, λ2, λ3 = 0.7, 0.2, 0.1 (§4, "Implementation details").
    pub const PAPER: LossWeights = LossWeights {
        l1: 0.7,
        dssim: 0.2,
        depth: 0.1,
        ..Self::ZERO
    };
    pub const L1: LossWeights = LossWeights {
        l1: 1.0,
        ..Self::ZERO
    };
    pub const L2: LossWeights = LossWeights {
        l2: 1.0,
        ..Self::ZERO
    };
}

/// The images a loss compares. RGB is interleaved, row-major, `width × height × 3`.
#[derive(Clone, Copy, Debug)]
pub struct LossInput<'a> {
    pub width: usize,
    pub height: usize,
    pub rgb: &'a [f32],
    pub target_rgb: &'a [f32],
    /// Rendered depth (whichever depth the caller supervises) and its target.
    pub depth: Option<&'a [f32]>,
    pub target_depth: Option<&'a [f32]>,
    /// Per-pixel weights `M` (paper Eq. 7); `None` means all ones.
    pub mask: Option<&'a [f32]>,
}

/// The value of each term (unweighted) and the weighted total.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LossTerms {
    pub total: f64,
    pub l1: f64,
    pub l2: f64,
    pub dssim: f64,
    pub depth: f64,
    /// Pixels that entered the depth term.
    pub depth_pixels: usize,
}

/// The loss and its gradients with respect to `rgb` and `depth`.
#[derive(Clone, Debug, Default)]
pub struct LossOutput {
    pub terms: LossTerms,
    pub grad_rgb: Vec<f32>,
    pub grad_depth: Option<Vec<f32>>,
}

fn sign(x: f32) -> f32 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

fn check_len(name: &str, got: usize, want: usize, w: usize, h: usize) -> Result<()> {
    if got != want {
        return Err(Error::invalid(format!(
            "{name} has {got} values, a {w}x{h} image needs {want}"
        )));
    }
    Ok(())
}

/// Evaluate the weighted loss and its gradients.
pub fn image_loss(inp: &LossInput, weights: &LossWeights) -> Result<LossOutput> {
    let (w, h) = (inp.width, inp.height);
    let npix = w * h;
    check_len("the rendered RGB", inp.rgb.len(), npix * 3, w, h)?;
    check_len("the target RGB", inp.target_rgb.len(), npix * 3, w, h)?;
    if let Some(m) = inp.mask {
        check_len("the loss mask", m.len(), npix, w, h)?;
        if let Some(bad) = m.iter().find(|v| !v.is_finite() || **v < 0.0) {
            return Err(Error::invalid(format!(
                "the loss mask holds {bad}; weights must be finite and non-negative"
            )));
        }
    }
    let m = |p: usize| inp.mask.map_or(1.0, |m| m[p]);
    let n = (npix * 3) as f64;
    let mut terms = LossTerms::default();
    let (gl1, gl2) = (weights.l1 / n as f32, weights.l2 * 2.0 / n as f32);
    // The L1/L2 terms on this thread while the SSIM runs beside them.
    let norms = || {
        let mut grad_rgb = vec![0f32; npix * 3];
        let (mut s1, mut s2) = (0f64, 0f64);
        for p in 0..npix {
            let mp = m(p);
            for c in 0..3 {
                let i = p * 3 + c;
                let d = mp * (inp.rgb[i] - inp.target_rgb[i]);
                s1 += d.abs() as f64;
                s2 += (d as f64) * (d as f64);
                // d(M·x)/dx = M.
                grad_rgb[i] = mp * (gl1 * sign(d) + gl2 * d);
            }
        }
        (grad_rgb, s1, s2)
    };
    let structure = || {
        (weights.dssim != 0.0).then(|| match inp.mask {
            None => ssim(inp.rgb, inp.target_rgb, w, h, 3, true),
            Some(mask) => {
                let scale = |img: &[f32]| -> Vec<f32> {
                    img.iter()
                        .enumerate()
                        .map(|(i, v)| mask[i / 3] * v)
                        .collect()
                };
                ssim(&scale(inp.rgb), &scale(inp.target_rgb), w, h, 3, true)
            }
        })
    };
    let ((mut grad_rgb, s1, s2), structure) = rayon::join(norms, structure);
    terms.l1 = s1 / n;
    terms.l2 = s2 / n;
    if let Some((s, g)) = structure {
        terms.dssim = 1.0 - s;
        for (i, (gr, gs)) in grad_rgb
            .iter_mut()
            .zip(g.expect("gradient requested"))
            .enumerate()
        {
            *gr -= weights.dssim * m(i / 3) * gs;
        }
    }
    let mut grad_depth = None;
    if let (Some(d), Some(dt)) = (inp.depth, inp.target_depth) {
        check_len("the rendered depth", d.len(), npix, w, h)?;
        check_len("the target depth", dt.len(), npix, w, h)?;
        let valid = |t: f32| t.is_finite() && t > 0.0;
        let count = dt.iter().filter(|t| valid(**t)).count();
        terms.depth_pixels = count;
        let mut g = vec![0f32; npix];
        if count > 0 {
            let scale = weights.depth / count as f32;
            let mut s = 0f64;
            for p in 0..npix {
                if valid(dt[p]) {
                    let e = m(p) * (d[p] - dt[p]);
                    s += e.abs() as f64;
                    g[p] = m(p) * scale * sign(e);
                }
            }
            terms.depth = s / count as f64;
        }
        grad_depth = Some(g);
    }
    terms.total = weights.l1 as f64 * terms.l1
        + weights.l2 as f64 * terms.l2
        + weights.dssim as f64 * terms.dssim
        + weights.depth as f64 * terms.depth;
    Ok(LossOutput {
        terms,
        grad_rgb,
        grad_depth,
    })
}

/// Mean absolute difference of two equally long slices, summed in f64 in order (what a
/// port's L1 is compared against, SPEC.md §14.1).
pub fn mean_abs_diff(x: &[f32], y: &[f32]) -> f64 {
    let sum: f64 = x.iter().zip(y).map(|(a, b)| f64::from((a - b).abs())).sum();
    sum / x.len().max(1) as f64
}

/// PSNR in dB of `x` against `y` (values in `[0, 1]`, both clamped to it first like INRIA's
/// evaluation, which clamps the render); infinite for identical images.
pub fn psnr(x: &[f32], y: &[f32]) -> f64 {
    assert_eq!(x.len(), y.len());
    let mut s = 0f64;
    for (&a, &b) in x.iter().zip(y) {
        let d = (a.clamp(0.0, 1.0) - b.clamp(0.0, 1.0)) as f64;
        s += d * d;
    }
    let mse = s / x.len().max(1) as f64;
    -10.0 * mse.log10()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Uniform;

    type Images = (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>);

    fn images(seed: u64, w: usize, h: usize) -> Images {
        let mut u = Uniform::new(seed);
        let x = (0..w * h * 3).map(|_| u.unit()).collect();
        let y = (0..w * h * 3).map(|_| u.unit()).collect();
        let d = (0..w * h).map(|_| u.range(1.0, 3.0)).collect();
        let mut dt: Vec<f32> = (0..w * h).map(|_| u.range(1.0, 3.0)).collect();
        dt[0] = 0.0;
        dt[1] = f32::NAN;
        let m = (0..w * h).map(|_| u.unit()).collect();
        (x, y, d, dt, m)
    }

    /// Every term's gradient against central differences of the f64 value.
    #[test]
    fn masked_loss_gradient_matches_finite_differences() {
        let (w, h) = (13, 12);
        let (x, y, d, dt, m) = images(5, w, h);
        let wts = LossWeights {
            l1: 0.7,
            l2: 0.3,
            dssim: 0.2,
            depth: 0.1,
        };
        let eval = |x: &[f32], d: &[f32]| {
            image_loss(
                &LossInput {
                    width: w,
                    height: h,
                    rgb: x,
                    target_rgb: &y,
                    depth: Some(d),
                    target_depth: Some(&dt),
                    mask: Some(&m),
                },
                &wts,
            )
            .unwrap()
        };
        let out = eval(&x, &d);
        assert_eq!(out.terms.depth_pixels, w * h - 2);
        let step = 1.0 / 4096.0;
        for i in (0..x.len()).step_by(5) {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i] += step;
            xm[i] -= step;
            let fd = (eval(&xp, &d).terms.total - eval(&xm, &d).terms.total) / (2.0 * step as f64);
            let g = out.grad_rgb[i] as f64;
            assert!(
                (fd - g).abs() < 2e-7 + 1e-3 * g.abs(),
                "rgb {i}: {fd} vs {g}"
            );
        }
        let gd = out.grad_depth.as_ref().unwrap();
        assert_eq!(
            (gd[0], gd[1]),
            (0.0, 0.0),
            "invalid targets get no gradient"
        );
        for p in (2..w * h).step_by(3) {
            let (mut dp, mut dm) = (d.clone(), d.clone());
            dp[p] += step;
            dm[p] -= step;
            let fd = (eval(&x, &dp).terms.total - eval(&x, &dm).terms.total) / (2.0 * step as f64);
            // The depth error m·(d − t) is an f32 product: its rounding (~1e-7 relative)
            // shows in the quotient, hence the relative bound.
            let g = gd[p] as f64;
            assert!(
                (fd - g).abs() < 1e-9 + 1e-3 * g.abs(),
                "depth {p}: {fd} vs {g}"
            );
        }
    }

    /// A mask of ones is the unmasked loss, bit for bit.
    #[test]
    fn unit_mask_equals_no_mask() {
        let (w, h) = (9, 7);
        let (x, y, _, _, _) = images(6, w, h);
        let ones = vec![1f32; w * h];
        let run = |mask| {
            image_loss(
                &LossInput {
                    width: w,
                    height: h,
                    rgb: &x,
                    target_rgb: &y,
                    depth: None,
                    target_depth: None,
                    mask,
                },
                &LossWeights::INRIA,
            )
            .unwrap()
        };
        let (a, b) = (run(None), run(Some(&ones)));
        assert_eq!(a.terms, b.terms);
        assert_eq!(a.grad_rgb, b.grad_rgb);
    }

    #[test]
    fn wrong_sizes_and_bad_masks_are_errors() {
        let x = vec![0f32; 12];
        let inp = LossInput {
            width: 2,
            height: 2,
            rgb: &x,
            target_rgb: &x[..9],
            depth: None,
            target_depth: None,
            mask: None,
        };
        assert!(image_loss(&inp, &LossWeights::L1).is_err());
        let m = [0.0, 1.0, f32::NAN, 0.0];
        let inp = LossInput {
            target_rgb: &x,
            mask: Some(&m),
            ..inp
        };
        let e = image_loss(&inp, &LossWeights::L1).unwrap_err();
        assert!(e.to_string().contains("NaN"), "{e}");
    }
}
