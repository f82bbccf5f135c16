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
//! Loop order: per tile, the tile's splats are gathered once into a contiguous list with the
//! rows each can reach; then each tile row (16 pixels, two AVX2 registers) walks the list
//! front to back with its state in registers, until all 16 pixels have stopped. Pixels are
//! independent, so the order in which groups run does not change any result.
//!
//! The per-pixel arithmetic is written once in scalar Rust ([`blend_lane`], the reference
//! form, [`Kernel::Scalar`]) and once with AVX2 intrinsics, operation for operation (same
//! order, no FMA, selects for branches), chosen at run time. Both give the same bits
//! (tests `simd_and_scalar_kernels_are_bit_identical`, `exp_and_ln_simd_match_scalar_bitwise`).

use super::RenderReport;
use super::plan::RenderPlan;
use super::project::{ALPHA_THRESHOLD, Projected, Splat};
use super::tile::{TILE_SIZE, TileBins};
use crate::math::fastexp::exp;
use crate::math::round::{ceil, floor};
use rayon::prelude::*;

/// Upper clamp of per-splat alpha (gsplat ≥ 1.5.4 and INRIA; gsplat ≤ 1.5.3 used 0.999).
pub const MAX_ALPHA: f32 = 0.99;
/// Blending stops before a splat that would bring transmittance to this or below.
pub const TRANSMITTANCE_STOP: f32 = 1e-4;
/// σ is clamped here before `exp` (exact: see the module docs).
pub const SIGMA_CLAMP: f32 = 30.0;
/// Floor of alpha in `ED = D / max(alpha, ·)` (gsplat).
pub const EXPECTED_DEPTH_EPS: f32 = 1e-10;

/// Which compiled form of the per-Gaussian (projection) and per-pixel (blend) kernels runs.
/// All give identical bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kernel {
    /// The fastest form this CPU supports, detected at run time: AVX-512F for the forward
    /// and backward blends and both projections (forward and backward), AVX2 elsewhere.
    #[default]
    Auto,
    /// AVX2 where detected, never AVX-512 (tests and benches compare the forms).
    Avx2,
    /// One pixel (one Gaussian) at a time, no vectorization: the reference form.
    Scalar,
}

impl Kernel {
    /// Whether the AVX2 forms run.
    pub(crate) fn avx2(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        return self != Kernel::Scalar && std::is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        false
    }
    /// Whether the AVX-512F forms run, where one exists.
    pub(crate) fn avx512(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        return self == Kernel::Auto && std::is_x86_feature_detected!("avx512f");
        #[cfg(not(target_arch = "x86_64"))]
        false
    }
}

/// Instruction sets of the blend kernel (const parameter of the band loop).
const ISA_SCALAR: u8 = 0;
const ISA_AVX2: u8 = 1;
const ISA_AVX512: u8 = 2;

/// Pixels walked together: one tile row (two AVX2 registers of f32).
const GROUP: usize = TILE_SIZE;
/// Splats gathered from a tile's list at a time (gsplat loads a block's worth, 256).
const BATCH: usize = 256;

/// A splat as one tile sees it: its data and its position in the tile's list plus one
/// (what `n_contrib` records).
#[derive(Clone, Copy, Debug)]
struct TileSplat {
    s: Splat,
    pos1: u32,
}

/// The rows `[lo, hi)` of a tile starting at image row `y0` (with `rows` rows) that splat
/// `gid` can reach: all rows, or with `cull_rows` those within `ry + 1` pixels of its centre
/// (beyond, α < 1/255: SPEC.md §5.4). Shared by the forward and backward passes.
pub(crate) fn splat_rows(
    p: &Projected,
    gid: usize,
    y0: usize,
    rows: usize,
    cull_rows: bool,
) -> (u32, u32) {
    if !cull_rows {
        return (0, rows as u32);
    }
    let my = p.splats[gid].mean[1];
    let ry = p.radii[gid][1] as f32 + 1.0;
    let lo = (floor(my - ry) - y0 as f32).max(0.0);
    let hi = (ceil(my + ry) - y0 as f32 + 1.0).min(rows as f32);
    (lo as u32, if hi > lo { hi as u32 } else { lo as u32 })
}

/// How many list entries ahead the gather prefetches splat data.
const PREFETCH_AHEAD: usize = 8;

/// Hint the cache to load what the gather will read of splat `gid` (its data and radii):
/// tile lists are in depth order, so these reads jump through memory and used to be the
/// composite's largest single stall (benches/README.md). No effect on any result.
#[inline(always)]
pub(crate) fn prefetch(p: &Projected, gid: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        if let (Some(s), Some(r)) = (p.splats.get(gid), p.radii.get(gid)) {
            // SAFETY: prefetching is a hint: it never faults and reads nothing visible; the
            // pointers come from live references anyway.
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>((s as *const Splat).cast());
                _mm_prefetch::<_MM_HINT_T0>((r as *const [i32; 2]).cast());
            }
        }
    }
}

/// Blend state of a group of pixels (one tile row).
#[derive(Clone, Copy)]
struct Group {
    t: [f32; GROUP],
    r: [f32; GROUP],
    g: [f32; GROUP],
    b: [f32; GROUP],
    d: [f32; GROUP],
    n: [u32; GROUP],
    /// `u32::MAX` while the pixel blends, 0 once it stopped (or lies outside the image).
    active: [u32; GROUP],
}

impl Group {
    fn new(valid_lanes: usize) -> Group {
        let mut active = [0; GROUP];
        for a in active.iter_mut().take(valid_lanes) {
            *a = u32::MAX;
        }
        Group {
            t: [1.0; GROUP],
            r: [0.0; GROUP],
            g: [0.0; GROUP],
            b: [0.0; GROUP],
            d: [0.0; GROUP],
            n: [0; GROUP],
            active,
        }
    }
}

/// A splat evaluated at one pixel offset `d = mean − p`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SplatAlpha {
    pub sigma: f32,
    /// `exp(−min(σ, 30))`.
    pub e: f32,
    /// `o·e` before the 0.99 clamp.
    pub a: f32,
    pub alpha: f32,
}

/// σ and α of a splat at offset `(dx, dy)`: the one scalar definition shared by the forward
/// and backward passes (the AVX2 kernels mirror it operation for operation).
#[inline(always)]
pub(crate) fn splat_alpha(s: &Splat, dx: f32, dy: f32) -> SplatAlpha {
    let sigma = 0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) + s.conic[1] * dx * dy;
    let e = exp(-(if sigma < SIGMA_CLAMP {
        sigma
    } else {
        SIGMA_CLAMP
    }));
    let a = s.opacity * e;
    let alpha = if a < MAX_ALPHA { a } else { MAX_ALPHA };
    SplatAlpha { sigma, e, a, alpha }
}

/// Blend one splat into one pixel. The single scalar definition of the per-pixel arithmetic.
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
    let SplatAlpha { sigma, alpha, .. } = splat_alpha(s, dx, dy);
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

/// Walk the tile's list for one group, lane by lane (the reference form, and the fallback
/// without AVX2). Returns the Gaussian-pixel evaluations (16 per splat visited).
#[inline(never)]
fn blend_group_lanes<const DEPTH: bool, const TRACK: bool>(
    list: &[TileSplat],
    idx: &[u16],
    px: &[f32; GROUP],
    py: f32,
    st: &mut Group,
) -> u64 {
    let mut pairs = 0;
    for &k in idx {
        let ts = &list[k as usize];
        if st.active.iter().all(|&a| a == 0) {
            break;
        }
        pairs += GROUP as u64;
        let dy = ts.s.mean[1] - py;
        #[allow(clippy::needless_range_loop)] // `l` indexes seven state arrays
        for l in 0..GROUP {
            let dx = ts.s.mean[0] - px[l];
            blend_lane::<DEPTH, TRACK>(
                &ts.s,
                dx,
                dy,
                ts.pos1,
                &mut st.t[l],
                &mut st.r[l],
                &mut st.g[l],
                &mut st.b[l],
                &mut st.d[l],
                &mut st.n[l],
                &mut st.active[l],
            );
        }
    }
    pairs
}

/// [`blend_group_lanes`] with AVX2 intrinsics: [`blend_lane`]'s operations one for one,
/// the group's state held in registers for the whole walk.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{
        ALPHA_THRESHOLD, GROUP, Group, MAX_ALPHA, SIGMA_CLAMP, TRANSMITTANCE_STOP, TileSplat,
    };
    use crate::math::fastexp::exp_avx2;
    use std::arch::x86_64::*;

    /// Registers per group: 16 pixels are two 8-lane halves.
    const H: usize = super::GROUP / 8;

    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn blend_group<const DEPTH: bool, const TRACK: bool>(
        list: &[TileSplat],
        idx: &[u16],
        px: &[f32; GROUP],
        py: f32,
        st: &mut Group,
    ) -> u64 {
        let c = |x: f32| _mm256_set1_ps(x);
        let zero = _mm256_setzero_ps();
        let (mut pxv, mut t, mut r, mut g, mut b, mut d) = (
            [zero; H], [zero; H], [zero; H], [zero; H], [zero; H], [zero; H],
        );
        let (mut n, mut act) = ([_mm256_setzero_si256(); H], [zero; H]);
        for h in 0..H {
            let o = 8 * h;
            // SAFETY: o + 8 <= GROUP, the length of every array read here.
            unsafe {
                pxv[h] = _mm256_loadu_ps(px.as_ptr().add(o));
                t[h] = _mm256_loadu_ps(st.t.as_ptr().add(o));
                r[h] = _mm256_loadu_ps(st.r.as_ptr().add(o));
                g[h] = _mm256_loadu_ps(st.g.as_ptr().add(o));
                b[h] = _mm256_loadu_ps(st.b.as_ptr().add(o));
                d[h] = _mm256_loadu_ps(st.d.as_ptr().add(o));
                n[h] = _mm256_loadu_si256(st.n.as_ptr().add(o) as *const __m256i);
                act[h] = _mm256_castsi256_ps(_mm256_loadu_si256(
                    st.active.as_ptr().add(o) as *const __m256i
                ));
            }
        }
        let mut pairs = 0;
        for &k in idx {
            let ts = &list[k as usize];
            if _mm256_movemask_ps(_mm256_or_ps(act[0], act[1])) == 0 {
                break;
            }
            pairs += GROUP as u64;
            let s = &ts.s;
            let dy = s.mean[1] - py;
            // (C·dy)·dy and dy are the same in every lane: computed once in scalar.
            let (cdd, dyv) = (c(s.conic[2] * dy * dy), c(dy));
            let (mx, ca, cb, op) = (c(s.mean[0]), c(s.conic[0]), c(s.conic[1]), c(s.opacity));
            let pos = _mm256_set1_epi32(ts.pos1 as i32);
            // σ, α and the mask of both halves first; a splat valid for no pixel of the row
            // runs on with an empty mask and changes no state (no branch: SPEC.md §5.7).
            let (mut alphas, mut valids) = ([zero; H], [zero; H]);
            for h in 0..H {
                let dx = _mm256_sub_ps(mx, pxv[h]);
                let sum = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(ca, dx), dx), cdd);
                let sigma = _mm256_add_ps(
                    _mm256_mul_ps(c(0.5), sum),
                    _mm256_mul_ps(_mm256_mul_ps(cb, dx), dyv),
                );
                // `min_ps(a, b)` is `a < b ? a : b` (b when unordered): the scalar select.
                let clamped = _mm256_min_ps(sigma, c(SIGMA_CLAMP));
                // SAFETY: this function runs only on CPUs with AVX2.
                let e = unsafe { exp_avx2(_mm256_xor_ps(clamped, c(-0.0))) };
                alphas[h] = _mm256_min_ps(_mm256_mul_ps(op, e), c(MAX_ALPHA));
                valids[h] = _mm256_and_ps(
                    act[h],
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_GE_OQ>(sigma, zero),
                        _mm256_cmp_ps::<_CMP_GE_OQ>(alphas[h], c(ALPHA_THRESHOLD)),
                    ),
                );
            }
            for h in 0..H {
                let (alpha, valid) = (alphas[h], valids[h]);
                let nt = _mm256_mul_ps(t[h], _mm256_sub_ps(c(1.0), alpha));
                let stop = _mm256_and_ps(
                    valid,
                    _mm256_cmp_ps::<_CMP_LE_OQ>(nt, c(TRANSMITTANCE_STOP)),
                );
                let blend = _mm256_andnot_ps(stop, valid);
                let w = _mm256_mul_ps(alpha, t[h]);
                let acc = |v: __m256, k: f32| {
                    _mm256_blendv_ps(v, _mm256_add_ps(v, _mm256_mul_ps(c(k), w)), blend)
                };
                r[h] = acc(r[h], s.color[0]);
                g[h] = acc(g[h], s.color[1]);
                b[h] = acc(b[h], s.color[2]);
                if DEPTH {
                    d[h] = acc(d[h], s.depth);
                }
                if TRACK {
                    n[h] = _mm256_blendv_epi8(n[h], pos, _mm256_castps_si256(blend));
                }
                t[h] = _mm256_blendv_ps(t[h], nt, blend);
                act[h] = _mm256_andnot_ps(stop, act[h]);
            }
        }
        for h in 0..H {
            let o = 8 * h;
            // SAFETY: as above.
            unsafe {
                _mm256_storeu_ps(st.t.as_mut_ptr().add(o), t[h]);
                _mm256_storeu_ps(st.r.as_mut_ptr().add(o), r[h]);
                _mm256_storeu_ps(st.g.as_mut_ptr().add(o), g[h]);
                _mm256_storeu_ps(st.b.as_mut_ptr().add(o), b[h]);
                _mm256_storeu_ps(st.d.as_mut_ptr().add(o), d[h]);
                _mm256_storeu_si256(st.n.as_mut_ptr().add(o) as *mut __m256i, n[h]);
                _mm256_storeu_si256(
                    st.active.as_mut_ptr().add(o) as *mut __m256i,
                    _mm256_castps_si256(act[h]),
                );
            }
        }
        pairs
    }
}

/// [`blend_group_lanes`] with AVX-512F intrinsics: one tile row is one 16-lane register,
/// the operations those of [`avx2::blend_group`] one for one, masks in mask registers.
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{
        ALPHA_THRESHOLD, GROUP, Group, MAX_ALPHA, SIGMA_CLAMP, TRANSMITTANCE_STOP, TileSplat,
    };
    use crate::math::fastexp::exp_avx512;
    use std::arch::x86_64::*;

    /// # Safety
    /// The CPU must support AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn blend_group<const DEPTH: bool, const TRACK: bool>(
        list: &[TileSplat],
        idx: &[u16],
        px: &[f32; GROUP],
        py: f32,
        st: &mut Group,
    ) -> u64 {
        let c = |x: f32| _mm512_set1_ps(x);
        let zero = _mm512_setzero_ps();
        // SAFETY: every array read or written here has exactly GROUP = 16 lanes.
        let (pxv, mut t, mut r, mut g, mut b, mut d, mut n, active) = unsafe {
            (
                _mm512_loadu_ps(px.as_ptr()),
                _mm512_loadu_ps(st.t.as_ptr()),
                _mm512_loadu_ps(st.r.as_ptr()),
                _mm512_loadu_ps(st.g.as_ptr()),
                _mm512_loadu_ps(st.b.as_ptr()),
                _mm512_loadu_ps(st.d.as_ptr()),
                _mm512_loadu_si512(st.n.as_ptr().cast()),
                _mm512_loadu_si512(st.active.as_ptr().cast()),
            )
        };
        let mut act: __mmask16 = _mm512_test_epi32_mask(active, active);
        let mut pairs = 0;
        for &k in idx {
            let ts = &list[k as usize];
            if act == 0 {
                break;
            }
            pairs += GROUP as u64;
            let s = &ts.s;
            let dy = s.mean[1] - py;
            let (cdd, dyv) = (c(s.conic[2] * dy * dy), c(dy));
            let dx = _mm512_sub_ps(c(s.mean[0]), pxv);
            let sum = _mm512_add_ps(_mm512_mul_ps(_mm512_mul_ps(c(s.conic[0]), dx), dx), cdd);
            let sigma = _mm512_add_ps(
                _mm512_mul_ps(c(0.5), sum),
                _mm512_mul_ps(_mm512_mul_ps(c(s.conic[1]), dx), dyv),
            );
            let clamped = _mm512_min_ps(sigma, c(SIGMA_CLAMP));
            let neg = _mm512_xor_si512(_mm512_castps_si512(clamped), _mm512_set1_epi32(i32::MIN));
            // SAFETY: this function runs only on CPUs with AVX-512F.
            let e = unsafe { exp_avx512(_mm512_castsi512_ps(neg)) };
            let alpha = _mm512_min_ps(_mm512_mul_ps(c(s.opacity), e), c(MAX_ALPHA));
            let valid = _mm512_mask_cmp_ps_mask::<_CMP_GE_OQ>(act, sigma, zero)
                & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(alpha, c(ALPHA_THRESHOLD));
            let nt = _mm512_mul_ps(t, _mm512_sub_ps(c(1.0), alpha));
            let stop = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(valid, nt, c(TRANSMITTANCE_STOP));
            let blend = valid & !stop;
            let w = _mm512_mul_ps(alpha, t);
            let acc = |v: __m512, k: f32| {
                _mm512_mask_blend_ps(blend, v, _mm512_add_ps(v, _mm512_mul_ps(c(k), w)))
            };
            r = acc(r, s.color[0]);
            g = acc(g, s.color[1]);
            b = acc(b, s.color[2]);
            if DEPTH {
                d = acc(d, s.depth);
            }
            if TRACK {
                n = _mm512_mask_blend_epi32(blend, n, _mm512_set1_epi32(ts.pos1 as i32));
            }
            t = _mm512_mask_blend_ps(blend, t, nt);
            act &= !stop;
        }
        // SAFETY: as above.
        unsafe {
            _mm512_storeu_ps(st.t.as_mut_ptr(), t);
            _mm512_storeu_ps(st.r.as_mut_ptr(), r);
            _mm512_storeu_ps(st.g.as_mut_ptr(), g);
            _mm512_storeu_ps(st.b.as_mut_ptr(), b);
            _mm512_storeu_ps(st.d.as_mut_ptr(), d);
            _mm512_storeu_si512(st.n.as_mut_ptr().cast(), n);
            _mm512_storeu_si512(
                st.active.as_mut_ptr().cast(),
                _mm512_maskz_mov_epi32(act, _mm512_set1_epi32(-1)),
            );
        }
        pairs
    }
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

/// Which images to write, fixed for a whole render (a subset of what the plan computes).
#[derive(Clone, Copy)]
pub struct Want {
    pub rgb: bool,
    pub alpha: bool,
    pub depth: bool,
    pub expected_depth: bool,
    pub backward_state: bool,
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn band_impl<const DEPTH: bool, const TRACK: bool, const ISA: u8>(
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
    // Reused for every tile of the band: no allocation in the loop.
    let mut batch: Vec<TileSplat> = Vec::with_capacity(BATCH);
    // Per tile row, the batch positions of the splats that can reach it, front to back:
    // each row walks only those (no data-dependent skipping in the kernel).
    let mut rows_idx: [Vec<u16>; TILE_SIZE] = std::array::from_fn(|_| Vec::with_capacity(BATCH));
    let mut groups = [Group::new(0); TILE_SIZE];
    for tx in 0..bins.tiles_x {
        let x0 = tx * TILE_SIZE;
        let cols = TILE_SIZE.min(width - x0);
        let mut px = [0f32; GROUP];
        for (l, v) in px.iter_mut().enumerate() {
            *v = (x0 + l) as f32 + 0.5;
        }
        for g in groups.iter_mut().take(rows) {
            *g = Group::new(cols);
        }
        let mut alive = [false; TILE_SIZE];
        alive[..rows].fill(cols > 0);
        // Gather the tile's list a batch at a time, like gsplat's shared-memory batches: rows
        // usually stop long before the end of a long list, so most splats are never loaded.
        let list = bins.tile(ty * bins.tiles_x + tx);
        for (bi, chunk) in list.chunks(BATCH).enumerate() {
            if !alive.iter().any(|&a| a) {
                break;
            }
            batch.clear();
            for r in rows_idx.iter_mut() {
                r.clear();
            }
            for (k, &gid) in chunk.iter().enumerate() {
                if let Some(&ahead) = chunk.get(k + PREFETCH_AHEAD) {
                    prefetch(p, ahead as usize);
                }
                let s = p.splats[gid as usize];
                let (lo, hi) = splat_rows(p, gid as usize, y0, rows, plan.cull_rows);
                if lo < hi {
                    let pos1 = (bi * BATCH + k) as u32 + 1;
                    for r in &mut rows_idx[lo as usize..hi as usize] {
                        r.push(batch.len() as u16);
                    }
                    batch.push(TileSplat { s, pos1 });
                }
            }
            for row in 0..rows {
                if !alive[row] {
                    continue;
                }
                let py = (y0 + row) as f32 + 0.5;
                let st = &mut groups[row];
                let idx = &rows_idx[row];
                #[cfg(target_arch = "x86_64")]
                let pairs = match ISA {
                    // SAFETY: ISA_AVX512 only inside `band_avx512`, entered after detection.
                    ISA_AVX512 => unsafe {
                        avx512::blend_group::<DEPTH, TRACK>(&batch, idx, &px, py, st)
                    },
                    // SAFETY: ISA_AVX2 only inside `band_avx2`, entered after detection.
                    ISA_AVX2 => unsafe {
                        avx2::blend_group::<DEPTH, TRACK>(&batch, idx, &px, py, st)
                    },
                    _ => blend_group_lanes::<DEPTH, TRACK>(&batch, idx, &px, py, st),
                };
                #[cfg(not(target_arch = "x86_64"))]
                let pairs = blend_group_lanes::<DEPTH, TRACK>(&batch, &rows_idx[row], &px, py, st);
                out.pairs += pairs;
                alive[row] = st.active.iter().any(|&a| a != 0);
            }
        }
        // Write the tile's pixels into the band.
        for (row, st) in groups.iter().enumerate().take(rows) {
            for l in 0..cols {
                let i = row * width + x0 + l;
                let t = st.t[l];
                if want.rgb {
                    let c = [st.r[l], st.g[l], st.b[l]];
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
                    out.depth[i] = st.d[l];
                }
                if want.expected_depth {
                    let den = if alpha > EXPECTED_DEPTH_EPS {
                        alpha
                    } else {
                        EXPECTED_DEPTH_EPS
                    };
                    out.expected_depth[i] = st.d[l] / den;
                }
                if want.backward_state {
                    out.final_t[i] = t;
                    out.n_contrib[i] = st.n[l];
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
    band_impl::<DEPTH, TRACK, ISA_AVX2>(ty, width, height, p, bins, plan, background, want)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn band_avx512<const DEPTH: bool, const TRACK: bool>(
    ty: usize,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
) -> BandOut {
    band_impl::<DEPTH, TRACK, ISA_AVX512>(ty, width, height, p, bins, plan, background, want)
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
    #[cfg(target_arch = "x86_64")]
    if kernel.avx512() {
        // SAFETY: the CPU supports AVX-512F (checked by `avx512`).
        return unsafe {
            band_avx512::<DEPTH, TRACK>(ty, width, height, p, bins, plan, background, want)
        };
    }
    #[cfg(target_arch = "x86_64")]
    if kernel.avx2() {
        // SAFETY: the CPU supports AVX2 (checked by `avx2`).
        return unsafe {
            band_avx2::<DEPTH, TRACK>(ty, width, height, p, bins, plan, background, want)
        };
    }
    band_impl::<DEPTH, TRACK, ISA_SCALAR>(ty, width, height, p, bins, plan, background, want)
}

/// The blend kernel alone: the bound [`composite`] is measured against
/// (`benches/forward.rs`, SPEC.md §5.7). `rows` tile rows (16 pixels each, at image rows
/// `row % 16`), each walking every splat of `splats` front to back from a fresh state with
/// the same kernel and arithmetic as [`composite`] (colour only: no depth, no backward
/// state), the list already gathered and small enough to stay in L1 (at most 256 splats),
/// the state in registers, no row culling, no output written. Rows are split over the
/// rayon pool in fixed chunks. Returns the Gaussian-pixel evaluations (16 per row and splat
/// visited, as [`RenderReport::pairs_evaluated`] counts them).
#[doc(hidden)]
pub fn bare_blend(splats: &[Splat], rows: usize, kernel: Kernel) -> u64 {
    assert!(
        splats.len() <= BATCH,
        "the bare kernel's list must fit one batch"
    );
    let list: Vec<TileSplat> = (0..splats.len())
        .map(|k| TileSplat {
            s: splats[k],
            pos1: k as u32 + 1,
        })
        .collect();
    let idx: Vec<u16> = (0..splats.len() as u16).collect();
    let px: [f32; GROUP] = std::array::from_fn(|l| l as f32 + 0.5);
    let (avx512, avx2) = (kernel.avx512(), kernel.avx2());
    let run = |row: usize| -> u64 {
        let py = (row % TILE_SIZE) as f32 + 0.5;
        let mut st = Group::new(GROUP);
        #[cfg(target_arch = "x86_64")]
        let pairs = if avx512 {
            // SAFETY: AVX-512F was detected above.
            unsafe { avx512::blend_group::<false, false>(&list, &idx, &px, py, &mut st) }
        } else if avx2 {
            // SAFETY: AVX2 was detected above.
            unsafe { avx2::blend_group::<false, false>(&list, &idx, &px, py, &mut st) }
        } else {
            blend_group_lanes::<false, false>(&list, &idx, &px, py, &mut st)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let pairs = blend_group_lanes::<false, false>(&list, &idx, &px, py, &mut st);
        std::hint::black_box(&st); // the final state is the kernel's only output
        pairs
    };
    (0..rows).into_par_iter().with_min_len(64).map(run).sum()
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
pub fn composite(
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
