//! Structural similarity as INRIA 3DGS trains with it (`utils/loss_utils.py`): an 11×11
//! Gaussian window with σ = 1.5 (normalized), zero padding of 5, `C1 = 0.01²`,
//! `C2 = 0.03²`, per channel, mean over all pixels and channels. Computed in f64 with a
//! separable window (INRIA convolves in f32 with the 2D outer product; the values agree to
//! f32 rounding), so the result does not depend on the thread count or the platform.
//!
//! Gradient: with `μ = G⊛x`, `E_xx = G⊛x²`, `E_xy = G⊛(x·y)` and `S(μx, μy, E_xx, E_yy, E_xy)`
//! per pixel, `dS̄/dx = (G⊛∂S/∂μx + 2x·G⊛∂S/∂E_xx + y·G⊛∂S/∂E_xy) / N`, the window being
//! symmetric so that its adjoint (with zero padding) is itself.

/// Window size and standard deviation (INRIA `ssim(window_size=11)`, `gaussian(11, 1.5)`).
pub const SSIM_WINDOW: usize = 11;
pub const SSIM_SIGMA: f64 = 1.5;
/// Stabilizers for unit-range images.
pub const SSIM_C1: f64 = 0.01 * 0.01;
pub const SSIM_C2: f64 = 0.03 * 0.03;

fn kernel() -> [f64; SSIM_WINDOW] {
    let mut k = [0.0; SSIM_WINDOW];
    let half = (SSIM_WINDOW / 2) as f64;
    for (i, v) in k.iter_mut().enumerate() {
        let d = i as f64 - half;
        *v = (-(d * d) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let s: f64 = k.iter().sum();
    k.map(|v| v / s)
}

/// Rows per parallel task of the blur: a fixed partition, and every output value is
/// computed by one task in the same order, so the result does not depend on the thread
/// count.
const ROWS_PER_TASK: usize = 8;

/// One output value of the 1D window at `i` over `src` (`n` samples, `stride` apart):
/// taps in ascending order, out-of-range taps skipped (zero padding).
#[inline(always)]
fn tap(src: &[f64], i: usize, n: usize, stride: usize, k: &[f64; SSIM_WINDOW]) -> f64 {
    let r = SSIM_WINDOW / 2;
    let mut acc = 0.0;
    if i >= r && i + r < n {
        let base = (i - r) * stride;
        for (t, kv) in k.iter().enumerate() {
            acc += kv * src[base + t * stride];
        }
    } else {
        for (t, kv) in k.iter().enumerate() {
            let j = i as isize + t as isize - r as isize;
            if j >= 0 && (j as usize) < n {
                acc += kv * src[j as usize * stride];
            }
        }
    }
    acc
}

/// Separable Gaussian blur of a planar `w × h` image with zero padding: horizontal pass,
/// then vertical.
fn blur(img: &[f64], w: usize, h: usize, k: &[f64; SSIM_WINDOW]) -> Vec<f64> {
    use rayon::prelude::*;
    let mut tmp = vec![0.0; w * h];
    tmp.par_chunks_mut(w * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(c, rows)| {
            for (ry, row) in rows.chunks_mut(w).enumerate() {
                let y = c * ROWS_PER_TASK + ry;
                let src = &img[y * w..(y + 1) * w];
                for (x, o) in row.iter_mut().enumerate() {
                    *o = tap(src, x, w, 1, k);
                }
            }
        });
    let mut out = vec![0.0; w * h];
    out.par_chunks_mut(w * ROWS_PER_TASK)
        .enumerate()
        .for_each(|(c, rows)| {
            for (ry, row) in rows.chunks_mut(w).enumerate() {
                let y = c * ROWS_PER_TASK + ry;
                for (x, o) in row.iter_mut().enumerate() {
                    *o = tap(&tmp[x..], y, h, w, k);
                }
            }
        });
    out
}

/// Mean SSIM of `x` against `y` (interleaved, `c` channels) and, if `grad`, dSSIM/dx.
pub fn ssim(
    x: &[f32],
    y: &[f32],
    w: usize,
    h: usize,
    c: usize,
    grad: bool,
) -> (f64, Option<Vec<f32>>) {
    assert_eq!(x.len(), w * h * c);
    assert_eq!(y.len(), w * h * c);
    let k = kernel();
    let n = (w * h * c) as f64;
    let mut total = 0.0;
    let mut g = grad.then(|| vec![0f32; x.len()]);
    for ch in 0..c {
        let xs: Vec<f64> = (0..w * h).map(|p| x[p * c + ch] as f64).collect();
        let ys: Vec<f64> = (0..w * h).map(|p| y[p * c + ch] as f64).collect();
        let prod = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(u, v)| u * v).collect::<Vec<f64>>();
        let (mx, my) = (blur(&xs, w, h, &k), blur(&ys, w, h, &k));
        let exx = blur(&prod(&xs, &xs), w, h, &k);
        let eyy = blur(&prod(&ys, &ys), w, h, &k);
        let exy = blur(&prod(&xs, &ys), w, h, &k);
        let (mut d_mu, mut d_exx, mut d_exy) =
            (vec![0.0; w * h], vec![0.0; w * h], vec![0.0; w * h]);
        for p in 0..w * h {
            let (ux, uy) = (mx[p], my[p]);
            let (sxx, syy, sxy) = (exx[p] - ux * ux, eyy[p] - uy * uy, exy[p] - ux * uy);
            let a1 = 2.0 * ux * uy + SSIM_C1;
            let a2 = 2.0 * sxy + SSIM_C2;
            let b1 = ux * ux + uy * uy + SSIM_C1;
            let b2 = sxx + syy + SSIM_C2;
            let s = a1 * a2 / (b1 * b2);
            total += s;
            if grad {
                let ds_dsxx = -a1 * a2 / (b1 * b2 * b2);
                let ds_dsxy = 2.0 * a1 / (b1 * b2);
                d_exx[p] = ds_dsxx;
                d_exy[p] = ds_dsxy;
                d_mu[p] = 2.0 * uy * a2 / (b1 * b2) - 2.0 * ux * a1 * a2 / (b1 * b1 * b2)
                    + ds_dsxx * (-2.0 * ux)
                    + ds_dsxy * (-uy);
            }
        }
        if let Some(g) = g.as_mut() {
            let (bm, bxx, bxy) = (
                blur(&d_mu, w, h, &k),
                blur(&d_exx, w, h, &k),
                blur(&d_exy, w, h, &k),
            );
            for p in 0..w * h {
                g[p * c + ch] = ((bm[p] + 2.0 * xs[p] * bxx[p] + ys[p] * bxy[p]) / n) as f32;
            }
        }
    }
    (total / n, g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Uniform;

    #[test]
    fn ssim_of_an_image_with_itself_is_one() {
        let mut u = Uniform::new(1);
        let x: Vec<f32> = (0..17 * 13 * 3).map(|_| u.unit()).collect();
        let (s, _) = ssim(&x, &x, 17, 13, 3, false);
        assert!((s - 1.0).abs() < 1e-12, "{s}");
    }

    /// The analytic gradient against central differences (h = 1e-3 on f32 inputs; the value
    /// is computed in f64, so the difference quotient is accurate to ~1e-9).
    #[test]
    fn ssim_gradient_matches_finite_differences() {
        let (w, h, c) = (14, 11, 2);
        let mut u = Uniform::new(2);
        let x: Vec<f32> = (0..w * h * c).map(|_| u.unit()).collect();
        let y: Vec<f32> = x
            .iter()
            .map(|v| (v + 0.3 * (u.unit() - 0.5)).clamp(0.0, 1.0))
            .collect();
        let (_, g) = ssim(&x, &y, w, h, c, true);
        let g = g.unwrap();
        for i in (0..x.len()).step_by(7) {
            let step = 1.0 / 1024.0; // exact in f32
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i] += step;
            xm[i] -= step;
            let fd = (ssim(&xp, &y, w, h, c, false).0 - ssim(&xm, &y, w, h, c, false).0)
                / (2.0 * step as f64);
            assert!(
                (fd - g[i] as f64).abs() < 1e-7 + 1e-4 * fd.abs(),
                "{i}: {fd} vs {}",
                g[i]
            );
        }
    }
}
