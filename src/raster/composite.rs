//! Front-to-back alpha blending of the sorted splats of each 16×16 tile.
//!
//! Per pixel and splat, in f32, no FMA, in this order (gsplat `RasterizeToPixels3DGSFwd.cu`):
//!
//! ```text
//! d = mean − p;  σ = 0.5·(A·dx·dx + C·dy·dy) + B·dx·dy;           skip if σ < 0
//! α = min(MAX_α, o·exp(−min(σ, 30)));  MAX_α 0.99 or 0.999 (profile) skip if α < 1/255
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
//! The per-pixel arithmetic is written once in scalar Rust (`blend_lane`, the reference
//! form, [`Kernel::Scalar`]) and once with AVX2 intrinsics, operation for operation (same
//! order, no FMA, selects for branches), chosen at run time. Both give the same bits
//! (tests `simd_and_scalar_kernels_are_bit_identical`, `exp_and_ln_simd_match_scalar_bitwise`).

use super::RenderReport;
use super::kernel::{ISA_AVX2, ISA_AVX512, ISA_SCALAR, Kernel};
use super::plan::RenderPlan;
use super::project::{ALPHA_THRESHOLD, Projected, Splat};
use super::schedule::longest_first;
use super::tile::{Shared, TILE_SIZE, TileBins};
use crate::math::fastexp::exp;
use rayon::prelude::*;
use std::ops::Range;

/// Upper clamp of per-splat alpha (INRIA and gsplat ≥ 1.5.4: [`super::Conventions::Inria`]).
pub const MAX_ALPHA: f32 = 0.99;
/// Upper clamp of per-splat alpha in gsplat 1.0–1.5.3 ([`super::Conventions::Gsplat`]).
pub const MAX_ALPHA_GSPLAT: f32 = 0.999;
/// Blending stops before a splat that would bring transmittance to this or below.
pub const TRANSMITTANCE_STOP: f32 = 1e-4;
/// σ is clamped here before `exp` (exact: see the module docs).
pub const SIGMA_CLAMP: f32 = 30.0;
/// Floor of alpha in `ED = D / max(alpha, ·)` (gsplat).
pub const EXPECTED_DEPTH_EPS: f32 = 1e-10;

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
/// (beyond, α < 1/255: SPEC.md §5.4): `lo = clamp(⌊my − ry⌋ − y0, 0, rows)`,
/// `hi = clamp(⌈my + ry⌉ − y0 + 1, lo, rows)` with `ry = radius_y + 1`, as integers
/// (truncating `my − ry` instead of flooring it changes only bounds that clamp to 0
/// anyway). Shared by the forward and backward passes, once per (tile, splat).
///
/// Computed in f32: `trunc`, `ceil` and the differences of integers below 2²⁴ are exact,
/// and a difference that rounds is beyond ±2²⁴, on the side of the clamp it would have been
/// on. A NaN centre, and tiles past row 2²⁴ where `y0` is not exact in f32, take the
/// integer definition ([`splat_rows_int`], which maps NaN to 0 like `f32 as i64`); both
/// agree everywhere else (`splat_rows_matches_float_definition`). The f32 form is a third
/// of the instructions of the saturating `f32 → i64` conversions (`perf`: they were ≈ 40 %
/// of the forward's samples outside its kernel).
#[inline(always)]
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
    let (top, bottom) = (my - ry, my + ry);
    if my.is_nan() || y0 >= 1 << 24 {
        return splat_rows_int(top, bottom, y0, rows);
    }
    let (y0, rows) = (y0 as f32, rows as f32);
    let lo = (top.trunc() - y0).clamp(0.0, rows);
    let hi = (bottom.ceil() - y0 + 1.0).clamp(lo, rows);
    (lo as u32, hi as u32)
}

/// [`splat_rows`] in integers from the splat's `top = my − ry` and `bottom = my + ry`:
/// `f32 as i64` truncates, saturates and maps NaN to 0 (for a bound `≥ 0` it is the floor,
/// and a negative one clamps to 0 either way).
#[cold]
fn splat_rows_int(top: f32, bottom: f32, y0: usize, rows: usize) -> (u32, u32) {
    let (y0, rows) = (y0 as i64, rows as i64);
    let lo = ((top as i64).saturating_sub(y0)).clamp(0, rows);
    let t = bottom as i64;
    let ceil = t.saturating_add(((t as f32) < bottom) as i64);
    let hi = ceil.saturating_sub(y0).saturating_add(1).clamp(lo, rows);
    (lo as u32, hi as u32)
}

/// 64-bit words of a row's membership set: one bit per position in a batch.
const WORDS: usize = BATCH / 64;

/// Which positions of a batch each tile row walks: bit `k % 64` of word `k / 64` of row
/// `r` is set when batch splat `k` can reach row `r` (its [`splat_rows`] range holds `r`).
type RowSets = [[u64; WORDS]; TILE_SIZE];

/// The set positions of a row's membership words, ascending (front to back).
#[derive(Clone)]
struct Members<'a> {
    words: &'a [u64],
    /// Position of bit 0 of `cur`.
    base: usize,
    cur: u64,
}

impl<'a> Members<'a> {
    #[inline(always)]
    fn new(words: &'a [u64]) -> Self {
        Members {
            words,
            base: 0usize.wrapping_sub(64),
            cur: 0,
        }
    }
}

impl Iterator for Members<'_> {
    type Item = usize;
    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        while self.cur == 0 {
            let (&w, rest) = self.words.split_first()?;
            self.words = rest;
            self.base = self.base.wrapping_add(64);
            self.cur = w;
        }
        let k = self.base + self.cur.trailing_zeros() as usize;
        self.cur &= self.cur - 1;
        Some(k)
    }
}

/// Transpose the per-splat row masks of a batch (`masks[k]`: bit `r` set when splat `k`
/// reaches row `r`; entries past the batch are 0) into per-row membership words:
/// `sets[r]` bit `k` = `masks[k]` bit `r`, for the first `words` words of each row.
/// The reference form; [`row_sets_avx2`] and [`row_sets_avx512`] give the same words.
#[inline(always)]
fn row_sets(masks: &[u32; BATCH], words: usize, sets: &mut RowSets) {
    for (r, set) in sets.iter_mut().enumerate() {
        for (w, word) in set.iter_mut().enumerate().take(words) {
            let mut bits = 0u64;
            for (j, &m) in masks[64 * w..64 * w + 64].iter().enumerate() {
                bits |= u64::from(m >> r & 1) << j;
            }
            *word = bits;
        }
    }
}

/// [`row_sets`] eight splats per instruction: each row's bit of eight masks shifted to
/// the sign and collected by `movemask`.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn row_sets_avx2(masks: &[u32; BATCH], words: usize, sets: &mut RowSets) {
    use std::arch::x86_64::*;
    for w in 0..words {
        let mut v = [_mm256_setzero_si256(); 8];
        for (q, v) in v.iter_mut().enumerate() {
            // SAFETY: 64·w + 8·q + 8 ≤ 64·words ≤ BATCH, the length of `masks`.
            *v = unsafe { _mm256_loadu_si256(masks.as_ptr().add(64 * w + 8 * q).cast()) };
        }
        for (r, set) in sets.iter_mut().enumerate() {
            let shift = _mm256_set1_epi32(31 - r as i32);
            let mut bits = 0u64;
            for (q, &v) in v.iter().enumerate() {
                let top = _mm256_castsi256_ps(_mm256_sllv_epi32(v, shift));
                bits |= u64::from(_mm256_movemask_ps(top) as u8) << (8 * q);
            }
            set[w] = bits;
        }
    }
}

/// [`row_sets`] sixteen splats per instruction (`vptestmd` into a mask register).
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn row_sets_avx512(masks: &[u32; BATCH], words: usize, sets: &mut RowSets) {
    use std::arch::x86_64::*;
    for w in 0..words {
        let mut v = [_mm512_setzero_si512(); 4];
        for (q, v) in v.iter_mut().enumerate() {
            // SAFETY: 64·w + 16·q + 16 ≤ 64·words ≤ BATCH, the length of `masks`.
            *v = unsafe { _mm512_loadu_si512(masks.as_ptr().add(64 * w + 16 * q).cast()) };
        }
        for (r, set) in sets.iter_mut().enumerate() {
            let bit = _mm512_set1_epi32(1 << r);
            let mut bits = 0u64;
            for (q, &v) in v.iter().enumerate() {
                bits |= u64::from(_mm512_test_epi32_mask(v, bit)) << (16 * q);
            }
            set[w] = bits;
        }
    }
}

/// How many list entries ahead the gather prefetches splat data: 8 hid the misses on one
/// thread but not on two, whose gathers meet a busier last-level cache (80×60, 2 threads:
/// 16 and 32 both cut the blend by ≈ 9 %, neither changed one thread; the backward's
/// gather uses 16 as well).
const PREFETCH_AHEAD: usize = 16;

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

/// The cut-offs and the α clamp as the kernels compare them (from
/// [`crate::raster::Cutoffs`] and [`crate::raster::Conventions`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Cut {
    /// Smallest blended α.
    pub alpha: f32,
    /// Transmittance at or below which blending stops.
    pub stop: f32,
    /// Upper clamp of α.
    pub max_alpha: f32,
}

impl Cut {
    pub(crate) fn new(plan: &RenderPlan) -> Cut {
        Cut {
            alpha: plan.cutoffs.alpha_threshold(),
            stop: plan.cutoffs.transmittance_stop,
            max_alpha: plan.conventions.max_alpha(),
        }
    }
    /// gsplat's cut-offs, INRIA's clamp (the defaults).
    const GSPLAT: Cut = Cut {
        alpha: ALPHA_THRESHOLD,
        stop: TRANSMITTANCE_STOP,
        max_alpha: MAX_ALPHA,
    };
}

/// Lanes of a half row: the unit of the blended-halves record (one AVX2 register).
const HALF_ROW: usize = GROUP / 2;

/// The blended-halves record of one batch as its rows are walked: `halves[k]` has bit
/// `2·row + h` set when some pixel of half `h` (columns `8h..8h + 8`) of tile row `row`
/// blended batch splat `k`; `shift` is `2·row` for the row being walked.
struct HalvesRecord {
    halves: [u32; BATCH],
    shift: u32,
}

impl HalvesRecord {
    fn new() -> Self {
        HalvesRecord {
            halves: [0; BATCH],
            shift: 0,
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
    /// `o·e` before the α clamp (0.99 or 0.999 by profile).
    pub a: f32,
    pub alpha: f32,
}

/// σ of a splat at offset `(dx, dy)`: the first step of [`splat_alpha`].
#[inline(always)]
pub(crate) fn splat_sigma(s: &Splat, dx: f32, dy: f32) -> f32 {
    0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) + s.conic[1] * dx * dy
}

/// σ and α of a splat at offset `(dx, dy)` under the α clamp `max_alpha`: the one scalar
/// definition shared by the forward and backward passes (the AVX2 kernels mirror it
/// operation for operation).
#[inline(always)]
pub(crate) fn splat_alpha(s: &Splat, dx: f32, dy: f32, max_alpha: f32) -> SplatAlpha {
    let sigma = splat_sigma(s, dx, dy);
    let e = exp(-(if sigma < SIGMA_CLAMP {
        sigma
    } else {
        SIGMA_CLAMP
    }));
    let a = s.opacity * e;
    let alpha = if a < max_alpha { a } else { max_alpha };
    SplatAlpha { sigma, e, a, alpha }
}

/// Blend one splat into one pixel; returns whether it blended. The single scalar definition
/// of the per-pixel arithmetic.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn blend_lane<const DEPTH: bool, const TRACK: bool>(
    cut: &Cut,
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
) -> bool {
    let SplatAlpha { sigma, alpha, .. } = splat_alpha(s, dx, dy, cut.max_alpha);
    let t0 = *t;
    let nt = t0 * (1.0 - alpha);
    let valid = (*active != 0) & (sigma >= 0.0) & (alpha >= cut.alpha);
    let stop = valid & (nt <= cut.stop);
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
    blend
}

/// Walk the tile's list for one group, lane by lane (the reference form, and the fallback
/// without AVX2). Returns the Gaussian-pixel evaluations (16 per splat visited). With
/// `TRACK`, `rec.halves[k]` gets bit `rec.shift + h` where some pixel of half `h` of the row
/// blended batch splat `k`.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn blend_group_lanes<const DEPTH: bool, const TRACK: bool>(
    list: &[TileSplat],
    sets: &[u64],
    px: &[f32; GROUP],
    py: f32,
    st: &mut Group,
    cut: &Cut,
    rec: &mut HalvesRecord,
) -> u64 {
    let mut pairs = 0;
    for k in Members::new(sets) {
        let ts = &list[k];
        if st.active.iter().all(|&a| a == 0) {
            break;
        }
        pairs += GROUP as u64;
        let dy = ts.s.mean[1] - py;
        let mut bits = 0;
        #[allow(clippy::needless_range_loop)] // `l` indexes seven state arrays
        for l in 0..GROUP {
            let dx = ts.s.mean[0] - px[l];
            let blended = blend_lane::<DEPTH, TRACK>(
                cut,
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
            bits |= u32::from(blended) << (l / HALF_ROW);
        }
        if TRACK {
            rec.halves[k] |= bits << rec.shift;
        }
    }
    pairs
}

/// [`blend_group_lanes`] with AVX2 intrinsics: [`blend_lane`]'s operations one for one,
/// the group's state held in registers for the whole walk.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{Cut, GROUP, Group, HalvesRecord, Members, SIGMA_CLAMP, TileSplat};
    use crate::math::fastexp::exp_avx2_in_range;
    use std::arch::x86_64::*;

    /// Registers per group: 16 pixels are two 8-lane halves.
    const H: usize = super::GROUP / 8;

    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn blend_group<const DEPTH: bool, const TRACK: bool>(
        list: &[TileSplat],
        sets: &[u64],
        px: &[f32; GROUP],
        py: f32,
        st: &mut Group,
        cut: &Cut,
        rec: &mut HalvesRecord,
    ) -> u64 {
        let c = |x: f32| _mm256_set1_ps(x);
        let zero = _mm256_setzero_ps();
        let (threshold, stop_at, clamp) = (c(cut.alpha), c(cut.stop), c(cut.max_alpha));
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
        for k in Members::new(sets) {
            let ts = &list[k];
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
                // −σ (up to the sign of a zero), and `max(−σ, −30) = −min(σ, 30)`
                // (`max_ps(a, b)` is `a > b ? a : b`, b when unordered, as `min_ps` was):
                // the exponential's argument lies in [−30, 0] in every valid lane (SPEC.md
                // §5.7). The upper clamp at 0 changes no valid lane; it keeps an invalid
                // one (σ < 0) from building a subnormal `2^k` (slow, never used).
                let neg_sigma = _mm256_sub_ps(
                    _mm256_mul_ps(c(-0.5), sum),
                    _mm256_mul_ps(_mm256_mul_ps(cb, dx), dyv),
                );
                let x = _mm256_min_ps(c(0.0), _mm256_max_ps(neg_sigma, c(-SIGMA_CLAMP)));
                // SAFETY: this function runs only on CPUs with AVX2.
                let e = unsafe { exp_avx2_in_range(x) };
                alphas[h] = _mm256_min_ps(_mm256_mul_ps(op, e), clamp);
                valids[h] = _mm256_and_ps(
                    act[h],
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_LE_OQ>(neg_sigma, zero),
                        _mm256_cmp_ps::<_CMP_GE_OQ>(alphas[h], threshold),
                    ),
                );
            }
            let mut bits = 0;
            for h in 0..H {
                let (alpha, valid) = (alphas[h], valids[h]);
                let nt = _mm256_mul_ps(t[h], _mm256_sub_ps(c(1.0), alpha));
                let stop = _mm256_and_ps(valid, _mm256_cmp_ps::<_CMP_LE_OQ>(nt, stop_at));
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
                    bits |= u32::from(_mm256_movemask_ps(blend) != 0) << h;
                }
                t[h] = _mm256_blendv_ps(t[h], nt, blend);
                act[h] = _mm256_andnot_ps(stop, act[h]);
            }
            if TRACK {
                rec.halves[k] |= bits << rec.shift;
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

#[cfg(target_arch = "x86_64")]
pub(crate) use avx512::splat_alpha16;

/// [`blend_group_lanes`] with AVX-512F intrinsics: one tile row is one 16-lane register,
/// the operations those of [`avx2::blend_group`] one for one, masks in mask registers.
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{Cut, GROUP, Group, HalvesRecord, Members, SIGMA_CLAMP, Splat, TileSplat};
    use crate::math::fastexp::exp_avx512_in_range;
    use std::arch::x86_64::*;

    /// −σ and α of splat `s` at the 16 pixel centres `px` of the row at `py` under the α
    /// clamp `clamp`: [`super::splat_alpha`]'s values lane for lane (the same bits), with
    /// −σ in place of σ (`σ ≥ 0` is `−σ ≤ 0`, both false for NaN). Round-to-nearest is
    /// symmetric, so `(−½)·sum − (B·dx)·dy` is `−(½·sum + (B·dx)·dy)` except for the sign
    /// of an exactly cancelling zero (`exp(+0)` and `exp(−0)` are the same 1.0), and
    /// `max(−σ, −30)` is `−min(σ, 30)` (NaN → −30 in both: the second operand), so the
    /// sign flip costs nothing. The exponential skips its range clamps: a lane with
    /// `σ ≥ 0` has its argument in `[−30, 0]`, and a lane with `σ < 0` or NaN is not valid,
    /// so its α (unspecified: normal, ∞ or NaN, as `vscalefps` saturates) is never used.
    /// Shared by the blend and the frozen-blend record.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub(crate) fn splat_alpha16(s: &Splat, px: __m512, py: f32, clamp: __m512) -> (__m512, __m512) {
        let c = |x: f32| _mm512_set1_ps(x);
        let dy = s.mean[1] - py;
        let (cdd, dyv) = (c(s.conic[2] * dy * dy), c(dy));
        let dx = _mm512_sub_ps(c(s.mean[0]), px);
        let sum = _mm512_add_ps(_mm512_mul_ps(_mm512_mul_ps(c(s.conic[0]), dx), dx), cdd);
        let neg_sigma = _mm512_sub_ps(
            _mm512_mul_ps(c(-0.5), sum),
            _mm512_mul_ps(_mm512_mul_ps(c(s.conic[1]), dx), dyv),
        );
        let x = _mm512_max_ps(neg_sigma, c(-SIGMA_CLAMP));
        // SAFETY: this function runs only on CPUs with AVX-512F.
        let e = unsafe { exp_avx512_in_range(x) };
        (
            neg_sigma,
            _mm512_min_ps(_mm512_mul_ps(c(s.opacity), e), clamp),
        )
    }

    /// # Safety
    /// The CPU must support AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn blend_group<const DEPTH: bool, const TRACK: bool>(
        list: &[TileSplat],
        sets: &[u64],
        px: &[f32; GROUP],
        py: f32,
        st: &mut Group,
        cut: &Cut,
        rec: &mut HalvesRecord,
    ) -> u64 {
        let c = |x: f32| _mm512_set1_ps(x);
        let zero = _mm512_setzero_ps();
        let (threshold, stop_at, clamp) = (c(cut.alpha), c(cut.stop), c(cut.max_alpha));
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
        for k in Members::new(sets) {
            let ts = &list[k];
            if act == 0 {
                break;
            }
            pairs += GROUP as u64;
            let s = &ts.s;
            let (neg_sigma, alpha) = splat_alpha16(s, pxv, py, clamp);
            // Active, σ ≥ 0 and α ≥ the threshold: the masked compares chain the ands.
            let valid = _mm512_mask_cmp_ps_mask::<_CMP_GE_OQ>(
                _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(act, neg_sigma, zero),
                alpha,
                threshold,
            );
            let nt = _mm512_mul_ps(t, _mm512_sub_ps(c(1.0), alpha));
            let stop = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(valid, nt, stop_at);
            let blend = valid & !stop;
            let w = _mm512_mul_ps(alpha, t);
            // `v + k·w` where blending, `v` elsewhere: one masked add.
            let acc = |v: __m512, k: f32| _mm512_mask_add_ps(v, blend, v, _mm512_mul_ps(c(k), w));
            r = acc(r, s.color[0]);
            g = acc(g, s.color[1]);
            b = acc(b, s.color[2]);
            if DEPTH {
                d = acc(d, s.depth);
            }
            if TRACK {
                n = _mm512_mask_blend_epi32(blend, n, _mm512_set1_epi32(ts.pos1 as i32));
                let bits = u32::from(blend & 0xff != 0) | u32::from(blend >> 8 != 0) << 1;
                rec.halves[k] |= bits << rec.shift;
            }
            t = _mm512_mask_mov_ps(t, blend, nt);
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

/// Most tasks of [`composite`] and of its backward: runs of whole tiles, many more than
/// threads, so that cheap and dear parts of the image even out between threads (bands of
/// tile rows were too coarse at the pipeline's 80×60: four bands for two threads). No
/// result depends on the split: each tile is computed alone, and results merge in tile
/// order.
pub(crate) const MAX_TASKS: usize = 64;

/// The output images, shared by the tasks of [`composite`], each of which writes only the
/// pixels of its own tiles (empty for images not wanted).
struct Images {
    rgb: Shared<f32>,
    alpha: Shared<f32>,
    depth: Shared<f32>,
    expected_depth: Shared<f32>,
    final_t: Shared<f32>,
    n_contrib: Shared<u32>,
    blend_halves: Shared<u32>,
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
fn tiles_impl<const DEPTH: bool, const TRACK: bool, const ISA: u8>(
    run: Range<usize>,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
    out: &Images,
) -> u64 {
    let mut pairs_total = 0;
    let cut = Cut::new(plan);
    // Reused for every tile of the run: no allocation in the loop.
    let mut batch: Vec<TileSplat> = Vec::with_capacity(BATCH);
    // Per batch splat, the tile rows it can reach as a bit mask (0 past the batch), and
    // per tile row the batch positions that reach it, front to back: each row walks only
    // those (no data-dependent skipping in the kernel).
    let mut masks = [0u32; BATCH];
    let mut sets: RowSets = [[0; WORDS]; TILE_SIZE];
    let mut groups = [Group::new(0); TILE_SIZE];
    let mut rec = HalvesRecord::new();
    for t in run {
        let (ty, tx) = (t / bins.tiles_x, t % bins.tiles_x);
        let (y0, x0) = (ty * TILE_SIZE, tx * TILE_SIZE);
        let rows = TILE_SIZE.min(height - y0);
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
        let list = bins.tile(t);
        for (bi, chunk) in list.chunks(BATCH).enumerate() {
            if !alive.iter().any(|&a| a) {
                break;
            }
            batch.clear();
            for (k, &gid) in chunk.iter().enumerate() {
                if let Some(&ahead) = chunk.get(k + PREFETCH_AHEAD) {
                    prefetch(p, ahead as usize);
                }
                let s = p.splats[gid as usize];
                let (lo, hi) = splat_rows(p, gid as usize, y0, rows, plan.cull_rows);
                if lo < hi {
                    let pos1 = (bi * BATCH + k) as u32 + 1;
                    // lo < hi ≤ 16: bits lo..hi.
                    masks[batch.len()] = (1u32 << hi) - (1u32 << lo);
                    batch.push(TileSplat { s, pos1 });
                }
            }
            let words = batch.len().div_ceil(64);
            masks[batch.len()..64 * words].fill(0);
            #[cfg(target_arch = "x86_64")]
            match ISA {
                // SAFETY: ISA_AVX512 only inside `tiles_avx512`, entered after detection.
                ISA_AVX512 => unsafe { row_sets_avx512(&masks, words, &mut sets) },
                // SAFETY: ISA_AVX2 only inside `tiles_avx2`, entered after detection.
                ISA_AVX2 => unsafe { row_sets_avx2(&masks, words, &mut sets) },
                _ => row_sets(&masks, words, &mut sets),
            }
            #[cfg(not(target_arch = "x86_64"))]
            row_sets(&masks, words, &mut sets);
            if TRACK {
                rec.halves[..batch.len()].fill(0);
            }
            for row in 0..rows {
                if !alive[row] {
                    continue;
                }
                let py = (y0 + row) as f32 + 0.5;
                let st = &mut groups[row];
                let set = &sets[row][..words];
                rec.shift = 2 * row as u32;
                let r = &mut rec;
                #[cfg(target_arch = "x86_64")]
                let pairs = match ISA {
                    // SAFETY: ISA_AVX512 only inside `tiles_avx512`, entered after detection.
                    ISA_AVX512 => unsafe {
                        avx512::blend_group::<DEPTH, TRACK>(&batch, set, &px, py, st, &cut, r)
                    },
                    // SAFETY: ISA_AVX2 only inside `tiles_avx2`, entered after detection.
                    ISA_AVX2 => unsafe {
                        avx2::blend_group::<DEPTH, TRACK>(&batch, set, &px, py, st, &cut, r)
                    },
                    _ => blend_group_lanes::<DEPTH, TRACK>(&batch, set, &px, py, st, &cut, r),
                };
                #[cfg(not(target_arch = "x86_64"))]
                let pairs = blend_group_lanes::<DEPTH, TRACK>(&batch, set, &px, py, st, &cut, r);
                pairs_total += pairs;
                alive[row] = st.active.iter().any(|&a| a != 0);
            }
            if TRACK && want.backward_state {
                // Positions of the chunk no row reaches keep the record's initial 0.
                let at = bins.offsets[t];
                for (ts, &h) in batch.iter().zip(&rec.halves) {
                    // SAFETY: intersection `at + pos1 − 1` belongs to tile `t`, which only
                    // this task writes ([`composite`] hands each tile to exactly one task).
                    unsafe { out.blend_halves.write(at + ts.pos1 as usize - 1, h) };
                }
            }
        }
        // Write the tile's pixels.
        // SAFETY (every `write` below): pixel `i` lies in tile `t`, which only this task
        // writes ([`composite`] hands each tile to exactly one task); `write` checks bounds.
        for (row, st) in groups.iter().enumerate().take(rows) {
            for l in 0..cols {
                let i = (y0 + row) * width + x0 + l;
                let t = st.t[l];
                if want.rgb {
                    let c = [st.r[l], st.g[l], st.b[l]];
                    for k in 0..3 {
                        let v = if plan.apply_background {
                            c[k] + t * background[k]
                        } else {
                            c[k]
                        };
                        unsafe { out.rgb.write(i * 3 + k, v) };
                    }
                }
                let alpha = 1.0 - t;
                if want.alpha {
                    unsafe { out.alpha.write(i, alpha) };
                }
                if want.depth {
                    unsafe { out.depth.write(i, st.d[l]) };
                }
                if want.expected_depth {
                    let den = if alpha > EXPECTED_DEPTH_EPS {
                        alpha
                    } else {
                        EXPECTED_DEPTH_EPS
                    };
                    unsafe { out.expected_depth.write(i, st.d[l] / den) };
                }
                if want.backward_state {
                    unsafe { out.final_t.write(i, t) };
                    unsafe { out.n_contrib.write(i, st.n[l]) };
                }
            }
        }
    }
    pairs_total
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn tiles_avx2<const DEPTH: bool, const TRACK: bool>(
    run: Range<usize>,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
    out: &Images,
) -> u64 {
    tiles_impl::<DEPTH, TRACK, ISA_AVX2>(run, width, height, p, bins, plan, background, want, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn tiles_avx512<const DEPTH: bool, const TRACK: bool>(
    run: Range<usize>,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
    out: &Images,
) -> u64 {
    tiles_impl::<DEPTH, TRACK, ISA_AVX512>(run, width, height, p, bins, plan, background, want, out)
}

#[allow(clippy::too_many_arguments)]
fn tiles<const DEPTH: bool, const TRACK: bool>(
    run: Range<usize>,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    plan: &RenderPlan,
    background: [f32; 3],
    want: Want,
    kernel: Kernel,
    out: &Images,
) -> u64 {
    #[cfg(target_arch = "x86_64")]
    if kernel.avx512() {
        // SAFETY: the CPU supports AVX-512F (checked by `avx512`).
        return unsafe {
            tiles_avx512::<DEPTH, TRACK>(run, width, height, p, bins, plan, background, want, out)
        };
    }
    #[cfg(target_arch = "x86_64")]
    if kernel.avx2() {
        // SAFETY: the CPU supports AVX2 (checked by `avx2`).
        return unsafe {
            tiles_avx2::<DEPTH, TRACK>(run, width, height, p, bins, plan, background, want, out)
        };
    }
    tiles_impl::<DEPTH, TRACK, ISA_SCALAR>(run, width, height, p, bins, plan, background, want, out)
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
    // Every row walks the whole list.
    let mut sets = [0u64; WORDS];
    for (w, word) in sets.iter_mut().enumerate() {
        *word = match splats.len().saturating_sub(64 * w) {
            0 => 0,
            n if n >= 64 => u64::MAX,
            n => (1u64 << n) - 1,
        };
    }
    let px: [f32; GROUP] = std::array::from_fn(|l| l as f32 + 0.5);
    let (avx512, avx2) = (kernel.avx512(), kernel.avx2());
    let cut = &Cut::GSPLAT;
    // `rec`: one per task, never written without `TRACK`.
    let run = |rec: &mut HalvesRecord, row: usize| -> u64 {
        let py = (row % TILE_SIZE) as f32 + 0.5;
        let mut st = Group::new(GROUP);
        let (l, s) = (&list, &sets);
        #[cfg(target_arch = "x86_64")]
        let pairs = if avx512 {
            // SAFETY: AVX-512F was detected above.
            unsafe { avx512::blend_group::<false, false>(l, s, &px, py, &mut st, cut, rec) }
        } else if avx2 {
            // SAFETY: AVX2 was detected above.
            unsafe { avx2::blend_group::<false, false>(l, s, &px, py, &mut st, cut, rec) }
        } else {
            blend_group_lanes::<false, false>(l, s, &px, py, &mut st, cut, rec)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let pairs = blend_group_lanes::<false, false>(l, s, &px, py, &mut st, cut, rec);
        std::hint::black_box(&st); // the final state is the kernel's only output
        pairs
    };
    (0..rows)
        .into_par_iter()
        .with_min_len(64)
        .map_init(HalvesRecord::new, run)
        .sum()
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
    /// Per (tile, Gaussian) intersection, in the order of `TileBins::ids`: bit `2·r + h` set
    /// when some pixel of half `h` (columns `8h..8h + 8`) of the tile's row `r` blended the
    /// splat. Backward state: the backward walks exactly these row halves.
    pub blend_halves: Option<Vec<u32>>,
}

/// Blend all tiles. Parallel over runs of tiles (`MAX_TASKS` at most); each tile's pixels
/// are computed by one task on their own, so the output does not depend on the thread count.
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
    let npix = width * height;
    let mut out = CompositeOut {
        rgb: want.rgb.then(|| vec![0.0; npix * 3]),
        alpha: want.alpha.then(|| vec![0.0; npix]),
        depth: want.depth.then(|| vec![0.0; npix]),
        expected_depth: want.expected_depth.then(|| vec![0.0; npix]),
        final_t: want.backward_state.then(|| vec![0.0; npix]),
        n_contrib: want.backward_state.then(|| vec![0; npix]),
        blend_halves: want.backward_state.then(|| vec![0; bins.ids.len()]),
    };
    // Runs of whole tiles, many more than threads (bands of tiles were too coarse to share
    // out at small images); each writes only its tiles' pixels.
    let shared = |v: &mut Option<Vec<f32>>| Shared::new(v.as_deref_mut().unwrap_or_default());
    let images = Images {
        rgb: shared(&mut out.rgb),
        alpha: shared(&mut out.alpha),
        depth: shared(&mut out.depth),
        expected_depth: shared(&mut out.expected_depth),
        final_t: shared(&mut out.final_t),
        n_contrib: Shared::new(out.n_contrib.as_deref_mut().unwrap_or_default()),
        blend_halves: Shared::new(out.blend_halves.as_deref_mut().unwrap_or_default()),
    };
    let n_tiles = bins.tiles_x * bins.tiles_y;
    let per = n_tiles.div_ceil(MAX_TASKS).max(1);
    let run = |k: usize| {
        let r = k * per..((k + 1) * per).min(n_tiles);
        let (w, h, bg, o) = (width, height, background, &images);
        match (plan.accumulate_depth, plan.track_backward_state) {
            (false, false) => tiles::<false, false>(r, w, h, p, bins, plan, bg, want, kernel, o),
            (true, false) => tiles::<true, false>(r, w, h, p, bins, plan, bg, want, kernel, o),
            (false, true) => tiles::<false, true>(r, w, h, p, bins, plan, bg, want, kernel, o),
            (true, true) => tiles::<true, true>(r, w, h, p, bins, plan, bg, want, kernel, o),
        }
    };
    // Costliest runs first; an integer sum: the same for any grouping.
    let costs = bins.run_costs(per, height);
    report.pairs_evaluated += longest_first(&costs, run).into_iter().sum::<u64>();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::round::{ceil, floor};

    /// Every form of the row-set transpose gives the same words, for random masks and every
    /// batch fill (words past `words` untouched).
    #[test]
    fn row_sets_forms_agree() {
        let mut u = crate::rng::Uniform::new(11);
        for len in [0usize, 1, 15, 16, 63, 64, 65, 130, 255, 256] {
            let mut masks = [0u32; BATCH];
            for m in masks.iter_mut().take(len) {
                let lo = (u.unit() * 16.0) as u32 % 16;
                let hi = lo + 1 + (u.unit() * (16 - lo) as f32) as u32 % (16 - lo);
                *m = (1u32 << hi) - (1u32 << lo);
            }
            let words = len.div_ceil(64);
            let mut want: RowSets = [[7; WORDS]; TILE_SIZE];
            row_sets(&masks, words, &mut want);
            for (r, set) in want.iter().enumerate() {
                for k in 0..64 * words {
                    assert_eq!(set[k / 64] >> (k % 64) & 1, u64::from(masks[k] >> r & 1));
                }
                assert!(set[words..].iter().all(|&w| w == 7));
                let members: Vec<usize> = Members::new(&set[..words]).collect();
                let expected: Vec<usize> = (0..len).filter(|&k| masks[k] >> r & 1 == 1).collect();
                assert_eq!(members, expected);
            }
            #[cfg(target_arch = "x86_64")]
            {
                if std::is_x86_feature_detected!("avx2") {
                    let mut got: RowSets = [[7; WORDS]; TILE_SIZE];
                    // SAFETY: AVX2 detected.
                    unsafe { row_sets_avx2(&masks, words, &mut got) };
                    assert_eq!(got, want, "avx2, {len} splats");
                }
                if std::is_x86_feature_detected!("avx512f") {
                    let mut got: RowSets = [[7; WORDS]; TILE_SIZE];
                    // SAFETY: AVX-512F detected.
                    unsafe { row_sets_avx512(&masks, words, &mut got) };
                    assert_eq!(got, want, "avx512, {len} splats");
                }
            }
        }
    }

    /// The integer row range is the float definition `lo = max(⌊my − ry⌋ − y0, 0)`,
    /// `hi = min(⌈my + ry⌉ − y0 + 1, rows)` (empty when `hi ≤ lo`), on edge values.
    /// One projected splat centred at row `my` with vertical radius `r` (for `splat_rows`).
    fn one_splat(my: f32, r: i32) -> Projected {
        Projected {
            splats: vec![Splat {
                mean: [0.0, my],
                ..Splat::default()
            }],
            radii: vec![[1, r]],
        }
    }

    #[test]
    fn splat_rows_f32_form_matches_the_integer_form() {
        // Every centre class (specials, both sides of each 2^k up to 2^25, random), every
        // radius class and tiles at 0, mid-image and either side of row 2^24: the f32 form
        // gives exactly the integer form's bounds, empty ranges included.
        let mut means = vec![
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        for k in 0..26 {
            let b = (1u64 << k) as f32;
            for m in [b, b.next_up(), b.next_down(), b + 0.5, b - 0.5] {
                means.extend([m, -m]);
            }
        }
        let mut u = crate::rng::Uniform::new(11);
        for _ in 0..2000 {
            means.push(u.range(-70_000.0, 70_000.0));
        }
        let radii = [0i32, 1, 2, 7, 15, 16, 17, 1000, 1 << 20, 1 << 24, i32::MAX];
        let y0s = [
            0usize,
            16,
            48,
            65520,
            (1 << 24) - 16,
            1 << 24,
            (1 << 24) + 16,
        ];
        for &my in &means {
            for &r in &radii {
                let p = one_splat(my, r);
                let ry = r as f32 + 1.0;
                for &y0 in &y0s {
                    for rows in [1usize, 7, 16] {
                        assert_eq!(
                            splat_rows(&p, 0, y0, rows, true),
                            splat_rows_int(my - ry, my + ry, y0, rows),
                            "my {my} r {r} y0 {y0} rows {rows}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn splat_rows_matches_float_definition() {
        let float_rows = |my: f32, r: i32, y0: usize, rows: usize| -> (u32, u32) {
            let ry = r as f32 + 1.0;
            let lo = (floor(my - ry) - y0 as f32).max(0.0);
            let hi = (ceil(my + ry) - y0 as f32 + 1.0).min(rows as f32);
            (lo as u32, if hi > lo { hi as u32 } else { lo as u32 })
        };
        let means = [
            -1e30f32, -70000.5, -17.0, -16.5, -1.0, -0.5, -0.0, 0.0, 0.25, 0.5, 1.0, 7.5, 15.99,
            16.0, 16.01, 31.5, 32.0, 100.7, 65535.5, 1e7, 3e7, 1e30,
        ];
        let radii = [0i32, 1, 2, 3, 15, 16, 17, 1000, 1 << 20, i32::MAX];
        for &my in &means {
            for &r in &radii {
                let p = one_splat(my, r);
                for y0 in [0usize, 16, 32, 48, 65520] {
                    for rows in [1usize, 7, 16] {
                        let (lo, hi) = splat_rows(&p, 0, y0, rows, true);
                        let (flo, fhi) = float_rows(my, r, y0, rows);
                        let empty = flo >= fhi;
                        assert_eq!(lo >= hi, empty, "my {my} r {r} y0 {y0} rows {rows}");
                        if !empty {
                            assert_eq!((lo, hi), (flo, fhi), "my {my} r {r} y0 {y0}");
                        }
                        assert!(hi as usize <= rows);
                    }
                }
            }
        }
    }
}
