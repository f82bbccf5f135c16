//! Backward of the blend (mirrors `raster::composite`), gsplat's formulation
//! (`RasterizeToPixels3DGSBwd.cu`, REFERENCE.md §A):
//!
//! ```text
//! walk back from n_contrib with T = T_final, buf = 0 (per channel and depth)
//!   recompute σ, α exactly as the forward; skip what the forward skipped
//!   ra = 1/max(1e-6, 1 − α);  T = T·ra;  fac = α·T
//!   v_c  += fac·v_rgb;   v_z += fac·v_D
//!   v_α   = Σ_k (c_k·T − buf_k·ra)·v_rgb_k + (z·T − buf_z·ra)·v_D
//!           + T_final·ra·v_alpha − T_final·ra·(bg · v_rgb)
//!   if o·e ≤ 0.99 (no gradient through the clamp):
//!       v_σ = −α·v_α;  v_conic += (½v_σ·dx², v_σ·dx·dy, ½v_σ·dy²)
//!       v_mean2d += v_σ·(A·dx + B·dy, B·dx + C·dy);  v_o += e·v_α
//!   buf += c·fac;  buf_z += z·fac
//! ```
//!
//! `ED = D / max(alpha, 1e-10)` is folded in first: `v_D += v_ED / max(alpha, 1e-10)` and, when
//! alpha > 1e-10, `v_alpha −= v_ED·D/alpha²`.
//!
//! Determinism: each tile is walked by one task, pixels in row-major order, each adding into
//! the tile's per-entry accumulators; the per-intersection results are then summed per
//! Gaussian in tile order. No atomics, no dependence on the thread count.

use crate::raster::composite::Kernel;
use crate::raster::composite::{
    EXPECTED_DEPTH_EPS, MAX_ALPHA, SIGMA_CLAMP, SplatAlpha, splat_alpha, splat_rows,
};
use crate::raster::project::{ALPHA_THRESHOLD, Projected, Splat};
use crate::raster::tile::{TILE_SIZE, TileBins};
use rayon::prelude::*;

/// Floor of `1 − α` when recovering transmittance (gsplat). With α ≤ 0.99 it never binds.
pub const RECOVER_EPS: f32 = 1e-6;

/// Gradient of the loss with respect to one projected splat.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SplatGrad {
    pub mean2d: [f32; 2],
    pub conic: [f32; 3],
    /// With respect to the activated opacity `o`.
    pub opacity: f32,
    pub color: [f32; 3],
    /// With respect to the splat's camera z as it enters D.
    pub depth: f32,
}

impl SplatGrad {
    fn add(&mut self, o: &SplatGrad) {
        for k in 0..2 {
            self.mean2d[k] += o.mean2d[k];
        }
        for k in 0..3 {
            self.conic[k] += o.conic[k];
            self.color[k] += o.color[k];
        }
        self.opacity += o.opacity;
        self.depth += o.depth;
    }
}

/// Upstream gradients per pixel (planar, row-major; `rgb` interleaved) and the forward
/// state the backward needs.
pub struct PixelGrads<'a> {
    pub v_rgb: Option<&'a [f32]>,
    pub v_alpha: Option<&'a [f32]>,
    pub v_depth: Option<&'a [f32]>,
    pub v_expected_depth: Option<&'a [f32]>,
    pub final_t: &'a [f32],
    pub n_contrib: &'a [u32],
    /// Forward D, needed only with `v_expected_depth`.
    pub depth: Option<&'a [f32]>,
}

/// Per-Gaussian splat gradients and the background gradient.
pub struct CompositeGrads {
    pub splats: Vec<SplatGrad>,
    pub background: [f32; 3],
    /// Gaussian-pixel pairs walked backward.
    pub pairs: u64,
}

struct BandGrads {
    /// One entry per intersection of the band's tiles, in `bins.ids` order.
    inter: Vec<SplatGrad>,
    background: [f64; 3],
    pairs: u64,
}

const LANES: usize = TILE_SIZE;
/// Per-splat contributions of one row, before the lane reduction: colour r, g, b, depth,
/// conic A, B, C, mean2d x, y, opacity.
const NC: usize = 10;

/// Backward state of one tile row (16 pixels), lane by lane.
#[derive(Clone, Copy, Default)]
struct RowState {
    t: [f32; LANES],
    t_final: [f32; LANES],
    v: [[f32; LANES]; 3],
    v_d: [f32; LANES],
    v_alpha: [f32; LANES],
    bg_dot: [f32; LANES],
    n: [u32; LANES],
    buf: [[f32; LANES]; 3],
    buf_z: [f32; LANES],
}

/// The sum of 16 lanes in the fixed tree order the AVX2 reduction uses:
/// `lane i + lane i+8`, then `+4`, then `+2`, then `+1`.
#[inline(always)]
pub(crate) fn sum16(v: &[f32; LANES]) -> f32 {
    let mut h = [0f32; 8];
    for i in 0..8 {
        h[i] = v[i] + v[i + 8];
    }
    let k = [h[0] + h[4], h[1] + h[5], h[2] + h[6], h[3] + h[7]];
    let m = [k[0] + k[2], k[1] + k[3]];
    m[0] + m[1]
}

/// Step the recovered transmittance back over a splat of opacity `alpha`: returns
/// `ra = 1/max(1e-6, 1 − α)`, the transmittance in front of the splat `T·ra`, and the splat's
/// weight `fac = α·T·ra`. Shared by the backward walk and the frozen-geometry record.
#[inline(always)]
pub(crate) fn recover(t_behind: f32, alpha: f32) -> (f32, f32, f32) {
    let one_minus = 1.0 - alpha;
    let ra = 1.0
        / if one_minus > RECOVER_EPS {
            one_minus
        } else {
            RECOVER_EPS
        };
    let t = t_behind * ra;
    (ra, t, alpha * t)
}

/// One lane of one splat, back to front: updates the lane state, writes the lane's
/// contributions (0 where nothing flows). The single scalar definition of the arithmetic.
#[inline(always)]
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)] // k, l index parallel arrays
fn lane<const GEOMETRY: bool>(
    s: &Splat,
    pos: u32,
    px: f32,
    py: f32,
    st: &mut RowState,
    l: usize,
    c: &mut [[f32; LANES]; NC],
) {
    let dx = s.mean[0] - px;
    let dy = s.mean[1] - py;
    let SplatAlpha { sigma, e, a, alpha } = splat_alpha(s, dx, dy);
    let valid = (pos < st.n[l]) & (sigma >= 0.0) & (alpha >= ALPHA_THRESHOLD);
    let (ra, t, fac) = recover(st.t[l], alpha);
    for k in 0..3 {
        c[k][l] = if valid { fac * st.v[k][l] } else { 0.0 };
    }
    if GEOMETRY {
        let tf = st.t_final[l];
        let v_a = (s.color[0] * t - st.buf[0][l] * ra) * st.v[0][l]
            + (s.color[1] * t - st.buf[1][l] * ra) * st.v[1][l]
            + (s.color[2] * t - st.buf[2][l] * ra) * st.v[2][l]
            + (s.depth * t - st.buf_z[l] * ra) * st.v_d[l]
            + tf * ra * st.v_alpha[l]
            - tf * ra * st.bg_dot[l];
        c[3][l] = if valid { fac * st.v_d[l] } else { 0.0 };
        let open = valid & (a <= MAX_ALPHA);
        let v_sigma = -a * v_a;
        c[4][l] = if open { 0.5 * v_sigma * dx * dx } else { 0.0 };
        c[5][l] = if open { v_sigma * dx * dy } else { 0.0 };
        c[6][l] = if open { 0.5 * v_sigma * dy * dy } else { 0.0 };
        c[7][l] = if open {
            v_sigma * (s.conic[0] * dx + s.conic[1] * dy)
        } else {
            0.0
        };
        c[8][l] = if open {
            v_sigma * (s.conic[1] * dx + s.conic[2] * dy)
        } else {
            0.0
        };
        c[9][l] = if open { e * v_a } else { 0.0 };
        for k in 0..3 {
            st.buf[k][l] = if valid {
                st.buf[k][l] + s.color[k] * fac
            } else {
                st.buf[k][l]
            };
        }
        st.buf_z[l] = if valid {
            st.buf_z[l] + s.depth * fac
        } else {
            st.buf_z[l]
        };
    }
    st.t[l] = if valid { t } else { st.t[l] };
}

/// Add a row's reduced contributions to the splat's accumulator (fixed field order).
#[inline(always)]
#[allow(clippy::needless_range_loop)]
fn add_row<const GEOMETRY: bool>(gr: &mut SplatGrad, c: &[[f32; LANES]; NC]) {
    for k in 0..3 {
        gr.color[k] += sum16(&c[k]);
    }
    if GEOMETRY {
        gr.depth += sum16(&c[3]);
        for k in 0..3 {
            gr.conic[k] += sum16(&c[4 + k]);
        }
        gr.mean2d[0] += sum16(&c[7]);
        gr.mean2d[1] += sum16(&c[8]);
        gr.opacity += sum16(&c[9]);
    }
}

/// Walk one row back to front, lane by lane (the reference form). Returns pairs visited.
#[inline(never)]
#[allow(clippy::needless_range_loop)]
fn row_lanes<const GEOMETRY: bool>(
    list: &[(Splat, u32, u32)],
    row: u32,
    px: &[f32; LANES],
    py: f32,
    st: &mut RowState,
    acc: &mut [SplatGrad],
) -> u64 {
    let max_n = st.n.iter().copied().max().unwrap_or(0) as usize;
    let mut pairs = 0;
    let mut c = [[0f32; LANES]; NC];
    for pos in (0..max_n).rev() {
        let (s, lo, hi) = &list[pos];
        if row < *lo || row >= *hi {
            continue;
        }
        pairs += LANES as u64;
        for l in 0..LANES {
            lane::<GEOMETRY>(s, pos as u32, px[l], py, st, l, &mut c);
        }
        add_row::<GEOMETRY>(&mut acc[pos], &c);
    }
    pairs
}

/// [`row_lanes`] with AVX2 intrinsics: [`lane`]'s operations one for one, two registers of
/// 8 lanes, and [`sum16`]'s reduction order.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{
        ALPHA_THRESHOLD, LANES, MAX_ALPHA, NC, RECOVER_EPS, RowState, SIGMA_CLAMP, Splat, SplatGrad,
    };
    use crate::math::fastexp::exp_avx2;
    use std::arch::x86_64::*;

    /// `sum16` of the 16 lanes `lo ‖ hi`, in the same tree order.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn hsum16(lo: __m256, hi: __m256) -> f32 {
        let h = _mm256_add_ps(lo, hi); // lane i + lane i+8
        let k = _mm_add_ps(_mm256_castps256_ps128(h), _mm256_extractf128_ps::<1>(h)); // +4
        let m = _mm_add_ps(k, _mm_movehl_ps(k, k)); // +2
        _mm_cvtss_f32(_mm_add_ss(m, _mm_shuffle_ps::<0b01>(m, m))) // +1
    }

    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    #[allow(clippy::needless_range_loop)] // h and k index parallel register arrays
    pub(super) unsafe fn row<const GEOMETRY: bool>(
        list: &[(Splat, u32, u32)],
        row: u32,
        px: &[f32; LANES],
        py: f32,
        st: &mut RowState,
        acc: &mut [SplatGrad],
    ) -> u64 {
        let c = |x: f32| _mm256_set1_ps(x);
        let zero = _mm256_setzero_ps();
        let ld = |a: &[f32; LANES], h: usize| -> __m256 {
            // SAFETY: h ∈ {0, 1}, so 8h + 8 <= 16 elements.
            unsafe { _mm256_loadu_ps(a.as_ptr().add(8 * h)) }
        };
        let max_n = st.n.iter().copied().max().unwrap_or(0) as usize;
        let mut pxv = [zero; 2];
        let (mut t, mut tf, mut va, mut vd, mut bgd) =
            ([zero; 2], [zero; 2], [zero; 2], [zero; 2], [zero; 2]);
        let (mut v, mut buf) = ([[zero; 2]; 3], [[zero; 2]; 3]);
        let mut bz = [zero; 2];
        let mut n = [_mm256_setzero_si256(); 2];
        for h in 0..2 {
            pxv[h] = ld(px, h);
            t[h] = ld(&st.t, h);
            tf[h] = ld(&st.t_final, h);
            va[h] = ld(&st.v_alpha, h);
            vd[h] = ld(&st.v_d, h);
            bgd[h] = ld(&st.bg_dot, h);
            bz[h] = ld(&st.buf_z, h);
            for k in 0..3 {
                v[k][h] = ld(&st.v[k], h);
                buf[k][h] = ld(&st.buf[k], h);
            }
            // SAFETY: as above.
            n[h] = unsafe { _mm256_loadu_si256(st.n.as_ptr().add(8 * h) as *const __m256i) };
        }
        // Unsigned `pos < n` as signed compare: counts stay far below 2^31.
        let mut pairs = 0;
        for pos in (0..max_n).rev() {
            let (s, lo, hi) = &list[pos];
            if row < *lo || row >= *hi {
                continue;
            }
            pairs += LANES as u64;
            let dy = s.mean[1] - py;
            let cdd = c(s.conic[2] * dy * dy);
            let dyv = c(dy);
            let posv = _mm256_set1_epi32(pos as i32);
            // First σ, α and the blend mask of both halves; a splat that blends no pixel of
            // the row changes nothing (its contributions are +0.0 and no state moves), so
            // skipping it is exact — and common, splats being narrower than a tile.
            let (mut dxs, mut es, mut as_, mut alphas, mut valids) =
                ([zero; 2], [zero; 2], [zero; 2], [zero; 2], [zero; 2]);
            for h in 0..2 {
                let active = _mm256_castsi256_ps(_mm256_cmpgt_epi32(n[h], posv));
                let dx = _mm256_sub_ps(c(s.mean[0]), pxv[h]);
                let sum = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(c(s.conic[0]), dx), dx), cdd);
                let sigma = _mm256_add_ps(
                    _mm256_mul_ps(c(0.5), sum),
                    _mm256_mul_ps(_mm256_mul_ps(c(s.conic[1]), dx), dyv),
                );
                let clamped = _mm256_min_ps(sigma, c(SIGMA_CLAMP));
                // SAFETY: AVX2 is available in this function.
                let e = unsafe { exp_avx2(_mm256_xor_ps(clamped, c(-0.0))) };
                let a = _mm256_mul_ps(c(s.opacity), e);
                let alpha = _mm256_min_ps(a, c(MAX_ALPHA));
                valids[h] = _mm256_and_ps(
                    active,
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_GE_OQ>(sigma, zero),
                        _mm256_cmp_ps::<_CMP_GE_OQ>(alpha, c(ALPHA_THRESHOLD)),
                    ),
                );
                (dxs[h], es[h], as_[h], alphas[h]) = (dx, e, a, alpha);
            }
            if _mm256_movemask_ps(_mm256_or_ps(valids[0], valids[1])) == 0 {
                continue;
            }
            let mut cv = [[zero; 2]; NC];
            for h in 0..2 {
                let (dx, e, a, alpha, valid) = (dxs[h], es[h], as_[h], alphas[h], valids[h]);
                let one_minus = _mm256_sub_ps(c(1.0), alpha);
                // `max_ps(a, b)` is `a > b ? a : b`: the scalar select with the operands so.
                let den = _mm256_max_ps(one_minus, c(RECOVER_EPS));
                let ra = _mm256_div_ps(c(1.0), den);
                let tn = _mm256_mul_ps(t[h], ra);
                let fac = _mm256_mul_ps(alpha, tn);
                let sel = |m: __m256, x: __m256| _mm256_and_ps(m, x);
                for k in 0..3 {
                    cv[k][h] = sel(valid, _mm256_mul_ps(fac, v[k][h]));
                }
                if GEOMETRY {
                    let term = |col: f32, b: __m256, vv: __m256| {
                        _mm256_mul_ps(
                            _mm256_sub_ps(_mm256_mul_ps(c(col), tn), _mm256_mul_ps(b, ra)),
                            vv,
                        )
                    };
                    let mut v_a = term(s.color[0], buf[0][h], v[0][h]);
                    v_a = _mm256_add_ps(v_a, term(s.color[1], buf[1][h], v[1][h]));
                    v_a = _mm256_add_ps(v_a, term(s.color[2], buf[2][h], v[2][h]));
                    v_a = _mm256_add_ps(v_a, term(s.depth, bz[h], vd[h]));
                    let tfra = _mm256_mul_ps(tf[h], ra);
                    v_a = _mm256_add_ps(v_a, _mm256_mul_ps(tfra, va[h]));
                    v_a = _mm256_sub_ps(v_a, _mm256_mul_ps(tfra, bgd[h]));
                    cv[3][h] = sel(valid, _mm256_mul_ps(fac, vd[h]));
                    let open = _mm256_and_ps(valid, _mm256_cmp_ps::<_CMP_LE_OQ>(a, c(MAX_ALPHA)));
                    let v_sigma = _mm256_mul_ps(_mm256_xor_ps(a, c(-0.0)), v_a);
                    let dyy = dyv;
                    cv[4][h] = sel(
                        open,
                        _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(c(0.5), v_sigma), dx), dx),
                    );
                    cv[5][h] = sel(open, _mm256_mul_ps(_mm256_mul_ps(v_sigma, dx), dyy));
                    cv[6][h] = sel(
                        open,
                        _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(c(0.5), v_sigma), dyy), dyy),
                    );
                    let gx = _mm256_add_ps(
                        _mm256_mul_ps(c(s.conic[0]), dx),
                        _mm256_mul_ps(c(s.conic[1]), dyy),
                    );
                    let gy = _mm256_add_ps(
                        _mm256_mul_ps(c(s.conic[1]), dx),
                        _mm256_mul_ps(c(s.conic[2]), dyy),
                    );
                    cv[7][h] = sel(open, _mm256_mul_ps(v_sigma, gx));
                    cv[8][h] = sel(open, _mm256_mul_ps(v_sigma, gy));
                    cv[9][h] = sel(open, _mm256_mul_ps(e, v_a));
                    for k in 0..3 {
                        let nb = _mm256_add_ps(buf[k][h], _mm256_mul_ps(c(s.color[k]), fac));
                        buf[k][h] = _mm256_blendv_ps(buf[k][h], nb, valid);
                    }
                    let nz = _mm256_add_ps(bz[h], _mm256_mul_ps(c(s.depth), fac));
                    bz[h] = _mm256_blendv_ps(bz[h], nz, valid);
                }
                t[h] = _mm256_blendv_ps(t[h], tn, valid);
            }
            // The same fields in the same order as `add_row`, each reduced like `sum16`.
            let gr = &mut acc[pos];
            for k in 0..3 {
                gr.color[k] += hsum16(cv[k][0], cv[k][1]);
            }
            if GEOMETRY {
                gr.depth += hsum16(cv[3][0], cv[3][1]);
                for k in 0..3 {
                    gr.conic[k] += hsum16(cv[4 + k][0], cv[4 + k][1]);
                }
                gr.mean2d[0] += hsum16(cv[7][0], cv[7][1]);
                gr.mean2d[1] += hsum16(cv[8][0], cv[8][1]);
                gr.opacity += hsum16(cv[9][0], cv[9][1]);
            }
        }
        pairs
    }
}

#[allow(clippy::too_many_arguments)]
fn band<const AVX2: bool, const GEOMETRY: bool>(
    ty: usize,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    cull_rows: bool,
    background: [f32; 3],
    g: &PixelGrads,
) -> BandGrads {
    let y0 = ty * TILE_SIZE;
    let rows = TILE_SIZE.min(height - y0);
    let first = bins.offsets[ty * bins.tiles_x];
    let last = bins.offsets[(ty + 1) * bins.tiles_x];
    let mut out = BandGrads {
        inter: vec![SplatGrad::default(); last - first],
        background: [0.0; 3],
        pairs: 0,
    };
    let mut list: Vec<(Splat, u32, u32)> = Vec::new();
    for tx in 0..bins.tiles_x {
        let t = ty * bins.tiles_x + tx;
        let x0 = tx * TILE_SIZE;
        let cols = TILE_SIZE.min(width - x0);
        let ids = bins.tile(t);
        let acc = &mut out.inter[bins.offsets[t] - first..bins.offsets[t + 1] - first];
        // Only the prefix some pixel blended is needed.
        let mut max_n = 0usize;
        for row in 0..rows {
            for l in 0..cols {
                max_n = max_n.max(g.n_contrib[(y0 + row) * width + x0 + l] as usize);
            }
        }
        list.clear();
        for &gid in &ids[..max_n] {
            let (lo, hi) = splat_rows(p, gid as usize, y0, rows, cull_rows);
            list.push((p.splats[gid as usize], lo, hi));
        }
        let mut px = [0f32; LANES];
        for (l, v) in px.iter_mut().enumerate() {
            *v = (x0 + l) as f32 + 0.5;
        }
        for row in 0..rows {
            let py = (y0 + row) as f32 + 0.5;
            let mut st = RowState::default();
            for l in 0..cols {
                let i = (y0 + row) * width + x0 + l;
                let (tf, v_rgb, v_alpha, v_d) = upstream(g, i);
                st.t[l] = tf;
                st.t_final[l] = tf;
                for (k, &v) in v_rgb.iter().enumerate() {
                    st.v[k][l] = v;
                    out.background[k] += (tf * v) as f64;
                }
                st.v_alpha[l] = v_alpha;
                st.v_d[l] = v_d;
                st.bg_dot[l] = (background[0] * v_rgb[0] + background[1] * v_rgb[1])
                    + background[2] * v_rgb[2];
                st.n[l] = g.n_contrib[i];
            }
            #[cfg(target_arch = "x86_64")]
            let pairs = if AVX2 {
                // SAFETY: AVX2 == true only when the CPU has it (checked by the caller).
                unsafe { avx2::row::<GEOMETRY>(&list, row as u32, &px, py, &mut st, acc) }
            } else {
                row_lanes::<GEOMETRY>(&list, row as u32, &px, py, &mut st, acc)
            };
            #[cfg(not(target_arch = "x86_64"))]
            let pairs = row_lanes::<GEOMETRY>(&list, row as u32, &px, py, &mut st, acc);
            out.pairs += pairs;
        }
    }
    out
}

/// One pixel's upstream gradients with ED folded in: (T_final, v_rgb, v_alpha, v_D).
#[inline]
fn upstream(g: &PixelGrads, i: usize) -> (f32, [f32; 3], f32, f32) {
    let t_final = g.final_t[i];
    let v_rgb = g
        .v_rgb
        .map_or([0.0; 3], |v| [v[3 * i], v[3 * i + 1], v[3 * i + 2]]);
    let mut v_alpha = g.v_alpha.map_or(0.0, |v| v[i]);
    let mut v_d = g.v_depth.map_or(0.0, |v| v[i]);
    if let Some(v_ed) = g.v_expected_depth {
        let alpha = 1.0 - t_final;
        let den = if alpha > EXPECTED_DEPTH_EPS {
            alpha
        } else {
            EXPECTED_DEPTH_EPS
        };
        v_d += v_ed[i] / den;
        if alpha > EXPECTED_DEPTH_EPS {
            let d = g
                .depth
                .expect("forward depth is required for expected-depth gradients")[i];
            v_alpha -= v_ed[i] * d / (alpha * alpha);
        }
    }
    (t_final, v_rgb, v_alpha, v_d)
}

/// Backward of [`crate::raster::composite::composite`]: per-Gaussian splat gradients.
#[allow(clippy::too_many_arguments)]
pub fn composite_backward(
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    cull_rows: bool,
    background: [f32; 3],
    g: &PixelGrads,
    geometry: bool,
    kernel: Kernel,
) -> CompositeGrads {
    #[cfg(target_arch = "x86_64")]
    let avx2 = kernel == Kernel::Auto && std::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    let avx2 = false;
    let run = |ty: usize| match (avx2, geometry) {
        (true, true) => band::<true, true>(ty, width, height, p, bins, cull_rows, background, g),
        (true, false) => band::<true, false>(ty, width, height, p, bins, cull_rows, background, g),
        (false, true) => band::<false, true>(ty, width, height, p, bins, cull_rows, background, g),
        (false, false) => {
            band::<false, false>(ty, width, height, p, bins, cull_rows, background, g)
        }
    };
    let bands: Vec<BandGrads> = (0..bins.tiles_y).into_par_iter().map(run).collect();
    let mut splats = vec![SplatGrad::default(); p.splats.len()];
    let mut bg = [0f64; 3];
    let mut pairs = 0;
    let mut k = 0;
    // Sum per Gaussian in tile order (bands are consecutive runs of `bins.ids`).
    for b in &bands {
        for gr in &b.inter {
            splats[bins.ids[k] as usize].add(gr);
            k += 1;
        }
        for (acc, v) in bg.iter_mut().zip(b.background) {
            *acc += v;
        }
        pairs += b.pairs;
    }
    CompositeGrads {
        splats,
        background: bg.map(|v| v as f32),
        pairs,
    }
}
