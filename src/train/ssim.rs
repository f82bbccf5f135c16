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

/// Separable Gaussian blur with zero padding of `n` planes of `w × h` values stored one
/// after the other: horizontal pass, then vertical. Every output value is
/// `Σ_t k[t]·v[t]` over the in-range taps in ascending `t`, accumulated from 0 — the loops
/// run over `x` innermost so they vectorize without changing any element's order of
/// operations (separate multiply and add, never fused), so the AVX2 build of the same code,
/// chosen at run time, gives the same bits. Planes are independent parallel tasks (a fixed
/// partition).
fn blur_planes(src: &[f64], w: usize, h: usize, k: &[f64; SSIM_WINDOW]) -> Vec<f64> {
    use rayon::prelude::*;
    let n = w * h;
    let mut out = vec![0.0; src.len()];
    #[cfg(target_arch = "x86_64")]
    let avx2 = std::arch::is_x86_feature_detected!("avx2");
    out.par_chunks_mut(n)
        .zip(src.par_chunks(n))
        .for_each(|(dst, plane)| {
            let mut tmp = vec![0.0; n];
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: AVX2 was detected at run time.
                unsafe { blur_plane_avx2(dst, plane, &mut tmp, w, h, k) };
                return;
            }
            blur_plane(dst, plane, &mut tmp, w, h, k);
        });
    out
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn blur_plane_avx2(
    dst: &mut [f64],
    plane: &[f64],
    tmp: &mut [f64],
    w: usize,
    h: usize,
    k: &[f64; SSIM_WINDOW],
) {
    blur_plane(dst, plane, tmp, w, h, k)
}

#[inline(always)]
fn blur_plane(
    dst: &mut [f64],
    plane: &[f64],
    tmp: &mut [f64],
    w: usize,
    h: usize,
    k: &[f64; SSIM_WINDOW],
) {
    let r = (SSIM_WINDOW / 2) as isize;
    for (row_out, row_in) in tmp.chunks_exact_mut(w).zip(plane.chunks_exact(w)) {
        for (t, &kv) in k.iter().enumerate() {
            let off = t as isize - r;
            let lo = (-off).max(0) as usize;
            let hi = (w as isize - off).clamp(0, w as isize) as usize;
            if lo >= hi {
                continue;
            }
            let src_row = &row_in[(lo as isize + off) as usize..(hi as isize + off) as usize];
            for (o, &v) in row_out[lo..hi].iter_mut().zip(src_row) {
                *o += kv * v;
            }
        }
    }
    for (y, row_out) in dst.chunks_exact_mut(w).enumerate() {
        for (t, &kv) in k.iter().enumerate() {
            let yy = y as isize + t as isize - r;
            if yy < 0 || yy >= h as isize {
                continue;
            }
            let src_row = &tmp[yy as usize * w..(yy as usize + 1) * w];
            for (o, &v) in row_out.iter_mut().zip(src_row) {
                *o += kv * v;
            }
        }
    }
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
    ssim_impl(x, y, w, h, c, grad, None)
}

/// The SSIM map: per pixel, the mean over channels of the windowed SSIM that [`ssim`]
/// averages (so `ssim` is the mean of this map over all pixels, up to summation order).
/// For scores over a pixel subset (existing / extrapolated pixels, SPEC.md §20.7).
pub fn ssim_map(x: &[f32], y: &[f32], w: usize, h: usize, c: usize) -> Vec<f64> {
    let mut map = vec![0.0; w * h];
    ssim_impl(x, y, w, h, c, false, Some(&mut map));
    map
}

fn ssim_impl(
    x: &[f32],
    y: &[f32],
    w: usize,
    h: usize,
    c: usize,
    grad: bool,
    mut map: Option<&mut [f64]>,
) -> (f64, Option<Vec<f32>>) {
    assert_eq!(x.len(), w * h * c);
    assert_eq!(y.len(), w * h * c);
    let k = kernel();
    let np = w * h;
    let n = (np * c) as f64;
    // Planes, channel by channel: x, y, x², y², x·y.
    let mut planes = vec![0.0; 5 * c * np];
    for ch in 0..c {
        let base = 5 * ch * np;
        for p in 0..np {
            let (a, b) = (x[p * c + ch] as f64, y[p * c + ch] as f64);
            planes[base + p] = a;
            planes[base + np + p] = b;
            planes[base + 2 * np + p] = a * a;
            planes[base + 3 * np + p] = b * b;
            planes[base + 4 * np + p] = a * b;
        }
    }
    let blurred = blur_planes(&planes, w, h, &k);
    // Per channel: the SSIM map's sum (in pixel order) and, for the gradient, the three
    // derivative planes dS/dμx, dS/dE_xx, dS/dE_xy.
    let mut total = 0.0;
    let mut deriv = if grad {
        vec![0.0; 3 * c * np]
    } else {
        Vec::new()
    };
    for ch in 0..c {
        let b = &blurred[5 * ch * np..5 * (ch + 1) * np];
        let (mx, my, exx, eyy, exy) = (
            &b[..np],
            &b[np..2 * np],
            &b[2 * np..3 * np],
            &b[3 * np..4 * np],
            &b[4 * np..],
        );
        for p in 0..np {
            let (ux, uy) = (mx[p], my[p]);
            let (sxx, syy, sxy) = (exx[p] - ux * ux, eyy[p] - uy * uy, exy[p] - ux * uy);
            let a1 = 2.0 * ux * uy + SSIM_C1;
            let a2 = 2.0 * sxy + SSIM_C2;
            let b1 = ux * ux + uy * uy + SSIM_C1;
            let b2 = sxx + syy + SSIM_C2;
            let v = a1 * a2 / (b1 * b2);
            total += v;
            if let Some(m) = map.as_deref_mut() {
                m[p] += v / c as f64;
            }
            if grad {
                let ds_dsxx = -a1 * a2 / (b1 * b2 * b2);
                let ds_dsxy = 2.0 * a1 / (b1 * b2);
                let d = &mut deriv[3 * ch * np..3 * (ch + 1) * np];
                d[p] = 2.0 * uy * a2 / (b1 * b2) - 2.0 * ux * a1 * a2 / (b1 * b1 * b2)
                    + ds_dsxx * (-2.0 * ux)
                    + ds_dsxy * (-uy);
                d[np + p] = ds_dsxx;
                d[2 * np + p] = ds_dsxy;
            }
        }
    }
    let g = grad.then(|| {
        let bd = blur_planes(&deriv, w, h, &k);
        let mut g = vec![0f32; x.len()];
        for ch in 0..c {
            let d = &bd[3 * ch * np..3 * (ch + 1) * np];
            for p in 0..np {
                let (xs, ys) = (x[p * c + ch] as f64, y[p * c + ch] as f64);
                g[p * c + ch] = ((d[p] + 2.0 * xs * d[np + p] + ys * d[2 * np + p]) / n) as f32;
            }
        }
        g
    });
    (total / n, g)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Uniform;

    /// The separable, vectorized blur equals a direct 2D window sum (f64, any order) to
    /// rounding, including the zero-padded borders.
    #[test]
    fn separable_blur_matches_direct_2d_window() {
        let (w, h) = (23, 17);
        let mut u = Uniform::new(4);
        let img: Vec<f64> = (0..2 * w * h).map(|_| u.unit() as f64).collect();
        let k = kernel();
        let fast = blur_planes(&img, w, h, &k);
        for p in 0..2 {
            for y in 0..h {
                for x in 0..w {
                    let mut acc = 0.0;
                    for (ty, ky) in k.iter().enumerate() {
                        for (tx, kx) in k.iter().enumerate() {
                            let (yy, xx) =
                                (y as isize + ty as isize - 5, x as isize + tx as isize - 5);
                            if (0..h as isize).contains(&yy) && (0..w as isize).contains(&xx) {
                                acc += ky * kx * img[p * w * h + yy as usize * w + xx as usize];
                            }
                        }
                    }
                    let got = fast[p * w * h + y * w + x];
                    assert!((got - acc).abs() < 1e-14, "({p},{x},{y}): {got} vs {acc}");
                }
            }
        }
    }

    /// The AVX2 build of the blur gives the bits of the generic build.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_blur_is_bit_identical() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let (w, h) = (37, 29);
        let mut u = Uniform::new(8);
        let img: Vec<f64> = (0..w * h).map(|_| u.unit() as f64 * 3.0 - 1.0).collect();
        let k = kernel();
        let (mut a, mut b, mut t) = (vec![0.0; w * h], vec![0.0; w * h], vec![0.0; w * h]);
        blur_plane(&mut a, &img, &mut t, w, h, &k);
        t.fill(0.0);
        // SAFETY: AVX2 detected above.
        unsafe { blur_plane_avx2(&mut b, &img, &mut t, w, h, &k) };
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b));
    }

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
