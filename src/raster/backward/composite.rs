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

use crate::math::fastexp::exp;
use crate::raster::composite::{EXPECTED_DEPTH_EPS, MAX_ALPHA, SIGMA_CLAMP, splat_rows};
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

#[allow(clippy::too_many_arguments)]
fn band(
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
        for row in 0..rows {
            let py = (y0 + row) as f32 + 0.5;
            for l in 0..cols {
                let i = (y0 + row) * width + x0 + l;
                let px = (x0 + l) as f32 + 0.5;
                out.pairs += pixel(
                    &list,
                    row as u32,
                    px,
                    py,
                    i,
                    background,
                    g,
                    acc,
                    &mut out.background,
                );
            }
        }
    }
    out
}

/// Walk one pixel back to front; returns the splats visited.
#[allow(clippy::too_many_arguments)]
#[inline]
fn pixel(
    list: &[(Splat, u32, u32)],
    row: u32,
    px: f32,
    py: f32,
    i: usize,
    bg: [f32; 3],
    g: &PixelGrads,
    acc: &mut [SplatGrad],
    v_bg: &mut [f64; 3],
) -> u64 {
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
    for k in 0..3 {
        v_bg[k] += (t_final * v_rgb[k]) as f64;
    }
    let bg_dot = (bg[0] * v_rgb[0] + bg[1] * v_rgb[1]) + bg[2] * v_rgb[2];
    let n = g.n_contrib[i] as usize;
    let mut t = t_final;
    let mut buf = [0f32; 3];
    let mut buf_z = 0f32;
    let mut visited = 0;
    for pos in (0..n).rev() {
        let (s, lo, hi) = &list[pos];
        if row < *lo || row >= *hi {
            continue;
        }
        visited += 1;
        // The forward's arithmetic, operation for operation.
        let dx = s.mean[0] - px;
        let dy = s.mean[1] - py;
        let sigma = 0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) + s.conic[1] * dx * dy;
        let e = exp(-(if sigma < SIGMA_CLAMP {
            sigma
        } else {
            SIGMA_CLAMP
        }));
        let a = s.opacity * e;
        let alpha = if a < MAX_ALPHA { a } else { MAX_ALPHA };
        // Exactly the forward's skip (`σ ≥ 0` fails for NaN too).
        if sigma.is_nan() || sigma < 0.0 || alpha < ALPHA_THRESHOLD {
            continue;
        }
        let one_minus = 1.0 - alpha;
        let ra = 1.0
            / if one_minus > RECOVER_EPS {
                one_minus
            } else {
                RECOVER_EPS
            };
        t *= ra;
        let fac = alpha * t;
        let gr = &mut acc[pos];
        let mut v_a = 0.0f32;
        for k in 0..3 {
            gr.color[k] += fac * v_rgb[k];
            v_a += (s.color[k] * t - buf[k] * ra) * v_rgb[k];
        }
        v_a += (s.depth * t - buf_z * ra) * v_d;
        v_a += t_final * ra * v_alpha;
        v_a -= t_final * ra * bg_dot;
        gr.depth += fac * v_d;
        if a <= MAX_ALPHA {
            let v_sigma = -a * v_a;
            gr.conic[0] += 0.5 * v_sigma * dx * dx;
            gr.conic[1] += v_sigma * dx * dy;
            gr.conic[2] += 0.5 * v_sigma * dy * dy;
            gr.mean2d[0] += v_sigma * (s.conic[0] * dx + s.conic[1] * dy);
            gr.mean2d[1] += v_sigma * (s.conic[1] * dx + s.conic[2] * dy);
            gr.opacity += e * v_a;
        }
        for (b, c) in buf.iter_mut().zip(s.color) {
            *b += c * fac;
        }
        buf_z += s.depth * fac;
    }
    visited
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
) -> CompositeGrads {
    let bands: Vec<BandGrads> = (0..bins.tiles_y)
        .into_par_iter()
        .map(|ty| band(ty, width, height, p, bins, cull_rows, background, g))
        .collect();
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
