//! Front-to-back alpha blending of the sorted splats of each 16×16 tile.
//!
//! Per pixel and splat, in f32, no FMA, in this order (gsplat `RasterizeToPixels3DGSFwd.cu`):
//!
//! ```text
//! d = mean − p;  σ = 0.5·(A·dx·dx + C·dy·dy) + B·dx·dy;           skip if σ < 0
//! α = min(0.99, o·exp(−min(σ, 30)));                               skip if α < 1/255
//! T' = T·(1 − α);  if T' ≤ 1e-4: stop before blending (exclusive)
//! w = α·T;  C += c·w;  D += z·w;  T = T'
//! ```
//!
//! `exp` is [`crate::math::fastexp::exp`]; clamping σ at 30 keeps `o·exp(−σ)` out of
//! denormals and changes nothing, since `exp(−30) < 1/255`.
//!
//! The blend of one splat over one tile row (16 pixels) is written once, lane by lane, in
//! [`blend_row`]. It is compiled three ways that give the same bits: as is (baseline
//! x86-64 / any target), inside an `avx2` function chosen at run time (LLVM vectorizes the
//! 16 lanes as two 8-wide vectors), and pixel by pixel ([`Kernel::Scalar`], the reference
//! the others are tested against). Neither path contracts to FMA, so every lane performs
//! the same IEEE operations as the scalar code.

use super::RenderReport;
use super::plan::RenderPlan;
use super::project::{ALPHA_THRESHOLD, Projected, Splat};
use super::tile::{TILE_SIZE, TileBins};
use crate::math::fastexp::exp;
use rayon::prelude::*;

/// Upper clamp of per-splat alpha (gsplat ≥ 1.5.4 and INRIA; gsplat ≤ 1.5.3 used 0.999).
pub const MAX_ALPHA: f32 = 0.99;
/// Blending stops before a splat that would bring transmittance to this or below.
pub const TRANSMITTANCE_STOP: f32 = 1e-4;
/// σ is clamped here before `exp` (exact: see the module docs).
pub const SIGMA_CLAMP: f32 = 30.0;
/// Floor of alpha in `ED = D / max(alpha, ·)` (gsplat).
pub const EXPECTED_DEPTH_EPS: f32 = 1e-10;

const LANES: usize = TILE_SIZE;

/// Which compiled form of the blend kernel runs. All give identical bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kernel {
    /// The fastest form this CPU supports (AVX2 when detected at run time).
    #[default]
    Auto,
    /// One pixel at a time, no vectorization: the reference form.
    Scalar,
}

/// Blend state of one tile, structure of arrays by row.
#[derive(Clone)]
struct TileState {
    t: [[f32; LANES]; TILE_SIZE],
    r: [[f32; LANES]; TILE_SIZE],
    g: [[f32; LANES]; TILE_SIZE],
    b: [[f32; LANES]; TILE_SIZE],
    d: [[f32; LANES]; TILE_SIZE],
    n: [[u32; LANES]; TILE_SIZE],
    active: [[u32; LANES]; TILE_SIZE],
}

impl TileState {
    fn new() -> Self {
        TileState {
            t: [[1.0; LANES]; TILE_SIZE],
            r: [[0.0; LANES]; TILE_SIZE],
            g: [[0.0; LANES]; TILE_SIZE],
            b: [[0.0; LANES]; TILE_SIZE],
            d: [[0.0; LANES]; TILE_SIZE],
            n: [[0; LANES]; TILE_SIZE],
            active: [[0; LANES]; TILE_SIZE],
        }
    }
}

/// Blend one splat into one pixel. The single definition of the per-pixel arithmetic.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn blend_lane<const DEPTH: bool, const TRACK: bool>(
    s: &Splat,
    dx: f32,
    dy: f32,
    pos1: u32,
    t: &mut f32,
    r: &mut f32,
    g: &mut f32,
    b: &mut f32,
    d: &mut f32,
    n: &mut u32,
    active: &mut u32,
) {
    let sigma = 0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) + s.conic[1] * dx * dy;
    let e = exp(-(if sigma < SIGMA_CLAMP {
        sigma
    } else {
        SIGMA_CLAMP
    }));
    let a = s.opacity * e;
    let alpha = if a < MAX_ALPHA { a } else { MAX_ALPHA };
    let t0 = *t;
    let nt = t0 * (1.0 - alpha);
    let valid = (*active != 0) & (sigma >= 0.0) & (alpha >= ALPHA_THRESHOLD);
    let stop = valid & (nt <= TRANSMITTANCE_STOP);
    let blend = valid & !stop;
    let w = alpha * t0;
    *r = if blend { *r + s.color[0] * w } else { *r };
    *g = if blend { *g + s.color[1] * w } else { *g };
    *b = if blend { *b + s.color[2] * w } else { *b };
    if DEPTH {
        *d = if blend { *d + s.depth * w } else { *d };
    }
    if TRACK {
        *n = if blend { pos1 } else { *n };
    }
    *t = if blend { nt } else { t0 };
    *active = if stop { 0 } else { *active };
}

/// Blend one splat into one tile row; returns whether any pixel of the row is still active.
#[inline(always)]
fn blend_row<const DEPTH: bool, const TRACK: bool>(
    s: &Splat,
    px: &[f32; LANES],
    py: f32,
    pos1: u32,
    st: &mut TileState,
    row: usize,
) -> bool {
    let dy = s.mean[1] - py;
    let (t, r, g, b) = (
        &mut st.t[row],
        &mut st.r[row],
        &mut st.g[row],
        &mut st.b[row],
    );
    let (d, n, act) = (&mut st.d[row], &mut st.n[row], &mut st.active[row]);
    let mut any = 0u32;
    for l in 0..LANES {
        let dx = s.mean[0] - px[l];
        blend_lane::<DEPTH, TRACK>(
            s,
            dx,
            dy,
            pos1,
            &mut t[l],
            &mut r[l],
            &mut g[l],
            &mut b[l],
            &mut d[l],
            &mut n[l],
            &mut act[l],
        );
        any |= act[l];
    }
    any != 0
}

/// The reference form: one pixel at a time.
#[inline(never)]
fn blend_row_scalar<const DEPTH: bool, const TRACK: bool>(
    s: &Splat,
    px: &[f32; LANES],
    py: f32,
    pos1: u32,
    st: &mut TileState,
    row: usize,
) -> bool {
    let dy = s.mean[1] - py;
    let mut any = false;
    for l in 0..LANES {
        // black_box keeps LLVM from re-vectorizing this loop.
        let l = std::hint::black_box(l);
        let dx = s.mean[0] - px[l];
        blend_lane::<DEPTH, TRACK>(
            s,
            dx,
            dy,
            pos1,
            &mut st.t[row][l],
            &mut st.r[row][l],
            &mut st.g[row][l],
            &mut st.b[row][l],
            &mut st.d[row][l],
            &mut st.n[row][l],
            &mut st.active[row][l],
        );
        any |= st.active[row][l] != 0;
    }
    any
}

/// Outputs of one band of 16 image rows.
#[derive(Default)]
struct BandOut {
    rgb: Vec<f32>,
    alpha: Vec<f32>,
    depth: Vec<f32>,
    expected_depth: Vec<f32>,
    final_t: Vec<f32>,
    n_contrib: Vec<u32>,
    pairs: u64,
}

/// What to write, fixed for a whole render.
#[derive(Clone, Copy)]
pub(crate) struct Want {
    pub rgb: bool,
    pub alpha: bool,
    pub depth: bool,
    pub expected_depth: bool,
    pub backward_state: bool,
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn band_impl<const DEPTH: bool, const TRACK: bool, const SCALAR: bool>(
    ty: usize,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
) -> BandOut {
    let y0 = ty * TILE_SIZE;
    let rows = TILE_SIZE.min(height - y0);
    let npix = rows * width;
    let mut out = BandOut {
        rgb: if want.rgb {
            vec![0.0; npix * 3]
        } else {
            Vec::new()
        },
        alpha: if want.alpha {
            vec![0.0; npix]
        } else {
            Vec::new()
        },
        depth: if want.depth {
            vec![0.0; npix]
        } else {
            Vec::new()
        },
        expected_depth: if want.expected_depth {
            vec![0.0; npix]
        } else {
            Vec::new()
        },
        final_t: if want.backward_state {
            vec![0.0; npix]
        } else {
            Vec::new()
        },
        n_contrib: if want.backward_state {
            vec![0; npix]
        } else {
            Vec::new()
        },
        pairs: 0,
    };
    let mut st = TileState::new();
    for tx in 0..bins.tiles_x {
        let x0 = tx * TILE_SIZE;
        let cols = TILE_SIZE.min(width - x0);
        // Reset the state; pixels outside the image start inactive.
        st.t = [[1.0; LANES]; TILE_SIZE];
        st.r = [[0.0; LANES]; TILE_SIZE];
        st.g = [[0.0; LANES]; TILE_SIZE];
        st.b = [[0.0; LANES]; TILE_SIZE];
        if DEPTH {
            st.d = [[0.0; LANES]; TILE_SIZE];
        }
        if TRACK {
            st.n = [[0; LANES]; TILE_SIZE];
        }
        let mut alive = [false; TILE_SIZE];
        for (row, a) in st.active.iter_mut().enumerate() {
            for (l, v) in a.iter_mut().enumerate() {
                *v = if row < rows && l < cols { 1 } else { 0 };
            }
            alive[row] = row < rows && cols > 0;
        }
        let mut alive_rows = rows;
        let mut px = [0f32; LANES];
        for (l, v) in px.iter_mut().enumerate() {
            *v = (x0 + l) as f32 + 0.5;
        }
        let list = bins.tile(ty * bins.tiles_x + tx);
        for (pos, &gid) in list.iter().enumerate() {
            let s = &p.splats[gid as usize];
            let (r0, r1) = if plan.cull_rows {
                // Rows beyond radius + 1 px have α < 1/255 (SPEC.md §5.4).
                let ry = p.radii[gid as usize][1] as f32 + 1.0;
                let lo = ((s.mean[1] - ry).floor() - y0 as f32).max(0.0);
                let hi = ((s.mean[1] + ry).ceil() - y0 as f32 + 1.0).min(rows as f32);
                (lo as usize, if hi > lo { hi as usize } else { lo as usize })
            } else {
                (0, rows)
            };
            let pos1 = pos as u32 + 1;
            #[allow(clippy::needless_range_loop)] // `row` indexes the tile state too
            for row in r0..r1 {
                if !alive[row] {
                    continue;
                }
                out.pairs += LANES as u64;
                let py = (y0 + row) as f32 + 0.5;
                let still = if SCALAR {
                    blend_row_scalar::<DEPTH, TRACK>(s, &px, py, pos1, &mut st, row)
                } else {
                    blend_row::<DEPTH, TRACK>(s, &px, py, pos1, &mut st, row)
                };
                if !still {
                    alive[row] = false;
                    alive_rows -= 1;
                }
            }
            if alive_rows == 0 {
                break;
            }
        }
        // Write the tile's pixels into the band.
        for row in 0..rows {
            for l in 0..cols {
                let i = row * width + x0 + l;
                let t = st.t[row][l];
                if want.rgb {
                    let c = [st.r[row][l], st.g[row][l], st.b[row][l]];
                    for k in 0..3 {
                        out.rgb[i * 3 + k] = if plan.apply_background {
                            c[k] + t * background[k]
                        } else {
                            c[k]
                        };
                    }
                }
                let alpha = 1.0 - t;
                if want.alpha {
                    out.alpha[i] = alpha;
                }
                if want.depth {
                    out.depth[i] = st.d[row][l];
                }
                if want.expected_depth {
                    let den = if alpha > EXPECTED_DEPTH_EPS {
                        alpha
                    } else {
                        EXPECTED_DEPTH_EPS
                    };
                    out.expected_depth[i] = st.d[row][l] / den;
                }
                if want.backward_state {
                    out.final_t[i] = t;
                    out.n_contrib[i] = st.n[row][l];
                }
            }
        }
    }
    out
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn band_avx2<const DEPTH: bool, const TRACK: bool>(
    ty: usize,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
) -> BandOut {
    band_impl::<DEPTH, TRACK, false>(ty, width, height, p, bins, plan, background, want)
}

#[allow(clippy::too_many_arguments)]
fn band<const DEPTH: bool, const TRACK: bool>(
    ty: usize,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
    kernel: Kernel,
) -> BandOut {
    if kernel == Kernel::Scalar {
        return band_impl::<DEPTH, TRACK, true>(ty, width, height, p, bins, plan, background, want);
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe {
            band_avx2::<DEPTH, TRACK>(ty, width, height, p, bins, plan, background, want)
        };
    }
    band_impl::<DEPTH, TRACK, false>(ty, width, height, p, bins, plan, background, want)
}

/// Final images of a composite, each present only when requested.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompositeOut {
    pub rgb: Option<Vec<f32>>,
    pub alpha: Option<Vec<f32>>,
    pub depth: Option<Vec<f32>>,
    pub expected_depth: Option<Vec<f32>>,
    pub final_t: Option<Vec<f32>>,
    pub n_contrib: Option<Vec<u32>>,
}

/// Blend all tiles. Parallel over bands of 16 rows; each band's pixels are computed by one
/// task in a fixed order, so the output does not depend on the thread count.
#[allow(clippy::too_many_arguments)]
pub(crate) fn composite(
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
    kernel: Kernel,
    report: &mut RenderReport,
) -> CompositeOut {
    let run = |ty: usize| match (plan.accumulate_depth, plan.track_backward_state) {
        (false, false) => {
            band::<false, false>(ty, width, height, p, bins, plan, background, want, kernel)
        }
        (true, false) => {
            band::<true, false>(ty, width, height, p, bins, plan, background, want, kernel)
        }
        (false, true) => {
            band::<false, true>(ty, width, height, p, bins, plan, background, want, kernel)
        }
        (true, true) => {
            band::<true, true>(ty, width, height, p, bins, plan, background, want, kernel)
        }
    };
    let bands: Vec<BandOut> = (0..bins.tiles_y).into_par_iter().map(run).collect();
    let npix = width * height;
    let mut out = CompositeOut {
        rgb: want.rgb.then(|| Vec::with_capacity(npix * 3)),
        alpha: want.alpha.then(|| Vec::with_capacity(npix)),
        depth: want.depth.then(|| Vec::with_capacity(npix)),
        expected_depth: want.expected_depth.then(|| Vec::with_capacity(npix)),
        final_t: want.backward_state.then(|| Vec::with_capacity(npix)),
        n_contrib: want.backward_state.then(|| Vec::with_capacity(npix)),
    };
    fn append<T: Copy>(dst: &mut Option<Vec<T>>, src: &[T]) {
        if let Some(v) = dst {
            v.extend_from_slice(src);
        }
    }
    for b in bands {
        report.pairs_evaluated += b.pairs;
        append(&mut out.rgb, &b.rgb);
        append(&mut out.alpha, &b.alpha);
        append(&mut out.depth, &b.depth);
        append(&mut out.expected_depth, &b.expected_depth);
        append(&mut out.final_t, &b.final_t);
        append(&mut out.n_contrib, &b.n_contrib);
    }
    out
}
