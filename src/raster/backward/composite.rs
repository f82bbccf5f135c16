//! Backward of the blend (mirrors `raster::composite`), gsplat's formulation
//! (gsplat v1.5.3 `RasterizeToPixels3DGSBwd.cu`):
//!
//! ```text
//! walk back from n_contrib with T = T_final, buf = 0 (per channel and depth)
//!   recompute σ, α exactly as the forward; skip what the forward skipped
//!   ra = 1/max(1e-6, 1 − α);  T = T·ra;  fac = α·T
//!   v_c  += fac·v_rgb;   v_z += fac·v_D
//!   v_α   = Σ_k (c_k·T − buf_k·ra)·v_rgb_k + (z·T − buf_z·ra)·v_D
//!           + T_final·ra·v_alpha − T_final·ra·(bg · v_rgb)
//!   if o·e ≤ MAX_α (0.99 or 0.999 by profile; no gradient through the clamp):
//!       v_σ = −α·v_α;  v_conic += (½v_σ·dx², v_σ·dx·dy, ½v_σ·dy²)
//!       v_mean2d += v_σ·(A·dx + B·dy, B·dx + C·dy);  v_o += e·v_α
//!   buf += c·fac;  buf_z += z·fac
//! ```
//!
//! `ED = D / max(alpha, 1e-10)` is folded in first: `v_D += v_ED / max(alpha, 1e-10)` and, when
//! alpha > 1e-10, `v_alpha −= v_ED·D/alpha²`.
//!
//! Loop order: per tile, the walked prefix of its list (up to the largest `n_contrib`) is
//! gathered once (prefetched: the gather is bound by cache misses), each splat some row
//! visits becoming an entry with the (row, half) visits it gets. The entries are then walked
//! back to front, each over its rows ascending (16 pixels a row: one AVX-512F register, two
//! AVX2 registers, or 16 scalar lanes — [`Kernel`] picks the form, all give the same bits):
//! every row meets its splats back to front, its state read from and written back to the
//! tile's 16 row states (L1-resident), while the entry's accumulators stay in registers and
//! are reduced as soon as its last row is done. Entry-major rather than row-major (each row
//! walking its own list with its state in registers): an entry has 3–4 row visits on a
//! trained scene, and walking rows made every visit read and write the entry's accumulators
//! in a list-sized array and every entry cost a push per visit; the same operations in the
//! same order per row and per entry, so the same bits. Nothing depends on how bands are
//! scheduled.
//!
//! Reduction order (SPEC.md §5.8): per (tile, splat) there are 8 lane-pair accumulators per
//! contribution, starting at +0.0; each row visit adds `c_j + c_{j+8}` to lane `j`
//! (`add_pairs`; AVX2 adds its two registers, AVX-512F the upper 8 lanes of its register to
//! the lower 8, then each adds the sum into the accumulator), rows in order; once per entry
//! the 8 lanes are reduced in a fixed tree
//! (`j + (j+4)`, then `+2`, `+1`: `sum8`). The per-(tile, splat) results are then summed
//! per Gaussian in tile order. Each (tile, splat) sum has one pairwise step, a chain over at
//! most 16 rows and a 3-level tree: as accurate as the former order (a 16-lane tree per row,
//! then a chain over the rows; the same depth), with one horizontal reduction per
//! (tile, splat) instead of one per row visit. No atomics, no dependence on the thread count.
//!
//! Exact skips (all tested against walking every (row, splat) of the prefix,
//! `backward_skips_are_bit_identical`, and against the scalar reference, which evaluates every
//! lane of every visit it is given, `backward_simd_and_scalar_are_bit_identical`). With the
//! plan's culling on, a row visits a splat only in the halves (8 lanes) where the forward
//! blended it: the forward records, per (tile, splat) intersection, the row halves where some
//! pixel blended the splat (`CompositeOut::blend_halves`, tested against the definition in
//! `kernels_agree_on_centred_and_degenerate_splats`). A lane blends in the forward exactly
//! when it is valid in the backward: `position < n_contrib` means the pixel was still
//! blending there, and σ and α are recomputed with the same bits, so `σ ≥ 0` and
//! `α ≥ 1/255` decide alike (the splat where the forward stopped lies at or past
//! `n_contrib`). Every other (row, half) would add only +0.0.
//!
//! In a visit, a splat that blends no pixel changes nothing (its contributions are +0.0,
//! accumulators are never −0.0, no state moves): the AVX2 kernel skips the rest of the
//! visit, and skips evaluating a half row (8 lanes) the record does not ask for. The
//! AVX-512F kernel evaluates the whole row when either half is asked for, masks the lanes of a half not asked for out of `valid` (so they contribute +0.0 and
//! move no state, exactly as the lanes AVX2 does not evaluate), and does not branch on a
//! visit where no lane blends: it runs with an empty mask (a branch there mispredicts on
//! real tile lists, SPEC.md §5.8).

use crate::raster::composite::MAX_TASKS;
use crate::raster::composite::{
    EXPECTED_DEPTH_EPS, SIGMA_CLAMP, SplatAlpha, splat_alpha, splat_rows,
};
use crate::raster::kernel::{ISA_AVX2, ISA_AVX512, ISA_SCALAR, Kernel};
use crate::raster::project::{ALPHA_THRESHOLD, Projected, Splat};
use crate::raster::schedule::longest_first;
use crate::raster::tile::{TILE_SIZE, TileBins};
use rayon::prelude::*;

/// Floor of `1 − α` when recovering transmittance (gsplat). With α ≤ 0.999 it never binds.
pub const RECOVER_EPS: f32 = 1e-6;

/// Gradient of the loss with respect to one projected splat (the fields of a [`Splat`],
/// in its order).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct SplatGrad {
    pub mean2d: [f32; 2],
    pub conic: [f32; 3],
    /// With respect to the activated opacity `o`.
    pub opacity: f32,
    pub color: [f32; 3],
    /// With respect to the splat's camera z as it enters D.
    pub depth: f32,
}

const _: () = assert!(size_of::<SplatGrad>() == size_of::<Splat>());

impl SplatGrad {
    /// The gradients' fields as one f32 slice (as [`Splat::floats`]).
    pub fn floats(s: &[SplatGrad]) -> &[f32] {
        // SAFETY: `SplatGrad` is `repr(C)` with only f32 fields and no padding (its size is
        // a `Splat`'s, ten f32), so a slice of them is a slice of f32 of ten times the
        // length, with f32's alignment; the borrow is carried over.
        unsafe { std::slice::from_raw_parts(s.as_ptr().cast::<f32>(), s.len() * 10) }
    }
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
    /// The forward's record of which row halves blended each (tile, splat) intersection
    /// (`CompositeOut::blend_halves`): with culling, the rows and halves walked.
    pub blend_halves: &'a [u32],
    /// Forward D, needed only with `v_expected_depth`.
    pub depth: Option<&'a [f32]>,
}

/// Per-Gaussian splat gradients and the background gradient.
pub struct CompositeGrads {
    pub splats: Vec<SplatGrad>,
    pub background: [f32; 3],
    /// Gaussian-pixel pairs walked backward: 16 per (row, splat within the row's reach
    /// before its last blended splat), skipped or not — the same count for every kernel
    /// and plan (the work unit).
    pub pairs: u64,
    /// Of those, the pairs of the row visits a kernel evaluated (16 per visit the exact skips
    /// kept): what [`bare_blend_backward`]'s rate is compared with.
    pub walked: u64,
}

/// The gradients of one task's run of tiles.
struct TileGrads {
    /// The Gaussian and its gradient per intersection some row of its tile walked (the
    /// others would add +0.0), tile by tile, within a tile grouped by bucket (`starts`).
    gids: Vec<u32>,
    grads: Vec<SplatGrad>,
    /// Per tile of the run, where each bucket's entries start (`buckets + 1` absolute
    /// indices into `gids` and `grads`; see [`sum_buckets`]): within a tile the entries are
    /// grouped by bucket, in list order within a bucket.
    starts: Vec<u32>,
    pairs: u64,
    walked: u64,
}

/// The per-Gaussian sum works on buckets of `1 << shift` consecutive Gaussians (of `n`;
/// returns `shift` and the number of buckets): at least 512, so that a bucket's gradients
/// (20 KiB) stay in L1 while every tile's entries of the bucket are added, and at most 256
/// buckets, so that the tiles' bucket starts stay small. The buckets are the sum's parallel work, each written by one thread.
/// Each tile writes its entries grouped by bucket as the walk makes them, so the sum reads
/// every bucket's in one run per tile. (Ranges of Gaussians that each scanned every entry
/// cost more on 2 threads than on 1: every thread read every entry and mispredicted the
/// test of its range on about half of them.)
fn sum_buckets(n: usize) -> (u32, usize) {
    let mut shift = 9;
    while n >> shift >= 256 {
        shift += 1;
    }
    (shift, n.div_ceil(1 << shift))
}

const LANES: usize = TILE_SIZE;
/// Per-splat contributions of one row, before the lane reduction: colour r, g, b, depth,
/// conic A, B, C, mean2d x, y, opacity.
const NC: usize = 10;

/// Backward state of one tile row (16 pixels), lane by lane.
#[derive(Clone, Copy, Default)]
#[repr(C, align(64))]
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

/// How far ahead in a tile's list the gather prefetches splats.
const PREFETCH: usize = 16;

/// Lanes of one AVX2 register: a half row, and the width of the lane-pair accumulators.
pub(crate) const HALF: usize = LANES / 2;

/// Accumulators of one (tile, splat) entry: per contribution, lane `j` holds
/// `Σ_rows (c_j + c_{j+8})`, rows in order ([`add_pairs`]); reduced once by [`sum8`].
type Acc = [[f32; HALF]; NC];

/// A splat of a tile's walked prefix that some row walks.
#[derive(Clone, Copy)]
struct Entry {
    s: Splat,
    /// Position in the tile's list (what `n_contrib` counts).
    pos: u32,
    /// The (row, half) visits it gets: bit `2·row + h` for the half `h` (lanes `8h..8h+8`)
    /// of tile row `row`.
    halves: u32,
}

/// Add one row visit's 16 lane contributions into the 8 lane-pair accumulators:
/// `acc_j += c_j + c_{j+8}` (the AVX2 kernel: one add of the two halves, one add into `acc`).
#[inline(always)]
pub(crate) fn add_pairs(acc: &mut [f32; HALF], c: &[f32; LANES]) {
    for j in 0..HALF {
        acc[j] += c[j] + c[j + HALF];
    }
}

/// The sum of 8 lane-pair accumulators in a fixed tree: `lane j + lane j+4`, then `+2`,
/// then `+1`.
#[inline(always)]
pub(crate) fn sum8(v: &[f32; HALF]) -> f32 {
    let k = [v[0] + v[4], v[1] + v[5], v[2] + v[6], v[3] + v[7]];
    let m = [k[0] + k[2], k[1] + k[3]];
    m[0] + m[1]
}

/// Bits `2·row` of a per-(row, half) mask.
const EVEN_BITS: u32 = 0x5555_5555;

/// Bit `row` of a 16-bit row mask moved to bit `2·row`.
#[inline(always)]
fn spread_rows(m: u32) -> u32 {
    let mut x = m & 0xffff;
    x = (x | x << 8) & 0x00ff_00ff;
    x = (x | x << 4) & 0x0f0f_0f0f;
    x = (x | x << 2) & 0x3333_3333;
    (x | x << 1) & EVEN_BITS
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
    max_alpha: f32,
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
    let SplatAlpha { sigma, e, a, alpha } = splat_alpha(s, dx, dy, max_alpha);
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
        let open = valid & (a <= max_alpha);
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

/// Contributions accumulated per (tile, splat): colour only, or all ten.
const fn fields(geometry: bool) -> usize {
    if geometry { NC } else { 3 }
}

/// Add a row visit's contributions to the entry's lane-pair accumulators.
#[inline(always)]
fn add_row<const GEOMETRY: bool>(acc: &mut Acc, c: &[[f32; LANES]; NC]) {
    for (a, c) in acc.iter_mut().zip(c).take(fields(GEOMETRY)) {
        add_pairs(a, c);
    }
}

/// The (tile, splat) gradient: each field's accumulators reduced by [`sum8`].
#[inline(always)]
#[allow(clippy::needless_range_loop)] // k indexes parallel arrays
fn reduce<const GEOMETRY: bool>(acc: &Acc) -> SplatGrad {
    let mut gr = SplatGrad::default();
    for k in 0..3 {
        gr.color[k] = sum8(&acc[k]);
    }
    if GEOMETRY {
        gr.depth = sum8(&acc[3]);
        for k in 0..3 {
            gr.conic[k] = sum8(&acc[4 + k]);
        }
        gr.mean2d = [sum8(&acc[7]), sum8(&acc[8])];
        gr.opacity = sum8(&acc[9]);
    }
    gr
}

/// [`reduce`] with the first eight fields in one AVX2 register: an 8×8 transpose of their
/// accumulators makes lane `j` of row `r` field `j`'s accumulator `r`, and the rows are
/// added in [`sum8`]'s tree (`((r0 + r4) + (r2 + r6)) + ((r1 + r5) + (r3 + r7))`), so every
/// field gets the same additions in the same order: the same bits.
///
/// Only inside a band compiled for AVX2 or AVX-512F (it uses AVX2 instructions).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn reduce_lanes<const GEOMETRY: bool>(acc: &Acc) -> SplatGrad {
    use crate::math::lanes::{F32x8, Lanes};
    if !GEOMETRY {
        return reduce::<false>(acc);
    }
    let mut r = [F32x8::splat(0.0); HALF];
    F32x8::load_columns(acc[..HALF].as_flattened(), HALF, &mut r);
    let sums = ((r[0] + r[4]) + (r[2] + r[6])) + ((r[1] + r[5]) + (r[3] + r[7]));
    let mut f = [0f32; 16];
    sums.write(&mut f);
    SplatGrad {
        color: [f[0], f[1], f[2]],
        depth: f[3],
        conic: [f[4], f[5], f[6]],
        mean2d: [f[7], sum8(&acc[8])],
        opacity: sum8(&acc[9]),
    }
}

/// Walk one entry (a splat of the tile's list) over the rows its record `halves` asks for
/// (bits `2·row + h`), rows ascending, every lane of a row evaluated (the reference form);
/// each row's state is read from and written back to `states`, and the entry's
/// accumulators start at +0.0 in `acc`.
#[inline(never)]
fn entry_lanes<const GEOMETRY: bool>(
    max_alpha: f32,
    e: &Entry,
    px: &[f32; LANES],
    y0: usize,
    states: &mut [RowState; LANES],
    acc: &mut Acc,
) {
    *acc = [[0.0; HALF]; NC];
    let mut c = [[0f32; LANES]; NC];
    let mut keep = (e.halves | e.halves >> 1) & EVEN_BITS;
    while keep != 0 {
        let row = keep.trailing_zeros() as usize / 2;
        keep &= keep - 1;
        let py = (y0 + row) as f32 + 0.5;
        for (l, &x) in px.iter().enumerate() {
            lane::<GEOMETRY>(max_alpha, &e.s, e.pos, x, py, &mut states[row], l, &mut c);
        }
        add_row::<GEOMETRY>(acc, &c);
    }
}

/// [`entry_lanes`] with AVX2 intrinsics: [`lane`]'s operations one for one, two registers of
/// 8 lanes, and [`add_pairs`]'s accumulation (halves added, then added into the entry).
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{
        ALPHA_THRESHOLD, Acc, EVEN_BITS, Entry, HALF, LANES, NC, RECOVER_EPS, RowState,
        SIGMA_CLAMP, fields,
    };
    use crate::math::fastexp::exp_avx2_in_range;
    use std::arch::x86_64::*;

    /// # Safety
    /// The CPU must support AVX2.
    #[target_feature(enable = "avx2")]
    #[allow(clippy::needless_range_loop)] // h and k index parallel register arrays
    pub(super) unsafe fn entry<const GEOMETRY: bool>(
        max_alpha: f32,
        e: &Entry,
        px: &[f32; LANES],
        y0: usize,
        states: &mut [RowState; LANES],
        acc: &mut Acc,
    ) {
        let c = |x: f32| _mm256_set1_ps(x);
        let zero = _mm256_setzero_ps();
        let ld = |a: &[f32; LANES], h: usize| -> __m256 {
            // SAFETY: h ∈ {0, 1}, so 8h + 8 <= 16 elements.
            unsafe { _mm256_loadu_ps(a.as_ptr().add(8 * h)) }
        };
        let st_ = |a: &mut [f32; LANES], h: usize, x: __m256| {
            // SAFETY: h ∈ {0, 1}, so 8h + 8 <= 16 elements.
            unsafe { _mm256_storeu_ps(a.as_mut_ptr().add(8 * h), x) }
        };
        *acc = [[0.0; HALF]; NC];
        let Entry { s, pos, halves } = *e;
        let pxv = [ld(px, 0), ld(px, 1)];
        let posv = _mm256_set1_epi32(pos as i32);
        let mut keep = (halves | halves >> 1) & EVEN_BITS;
        // Unsigned `pos < n` as signed compare: counts stay far below 2^31.
        while keep != 0 {
            let b = keep.trailing_zeros();
            keep &= keep - 1;
            let row = b as usize / 2;
            let halves = halves >> b & 0b11;
            let st = &mut states[row];
            let py = (y0 + row) as f32 + 0.5;
            let dy = s.mean[1] - py;
            let cdd = c(s.conic[2] * dy * dy);
            let dyv = c(dy);
            // First σ, α and the blend mask of both halves; a splat that blends no pixel of
            // the row (or of a half) changes nothing there (its contributions are +0.0 and no
            // state moves), so skipping it is exact — and common, splats being narrower than
            // a tile. A half the record does not ask for is not even evaluated.
            let (mut dxs, mut es, mut as_, mut alphas, mut valids) =
                ([zero; 2], [zero; 2], [zero; 2], [zero; 2], [zero; 2]);
            for h in 0..2 {
                if halves & (1 << h) == 0 {
                    continue;
                }
                // SAFETY: h ∈ {0, 1}, so 8h + 8 <= 16 elements.
                let n = unsafe { _mm256_loadu_si256(st.n.as_ptr().add(8 * h).cast()) };
                let active = _mm256_castsi256_ps(_mm256_cmpgt_epi32(n, posv));
                let dx = _mm256_sub_ps(c(s.mean[0]), pxv[h]);
                let sum = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(c(s.conic[0]), dx), dx), cdd);
                // −σ and the exponential in range, as the forward's AVX2 form (SPEC.md
                // §5.7; the clamp at 0 keeps invalid lanes off subnormals).
                let neg_sigma = _mm256_sub_ps(
                    _mm256_mul_ps(c(-0.5), sum),
                    _mm256_mul_ps(_mm256_mul_ps(c(s.conic[1]), dx), dyv),
                );
                let x = _mm256_min_ps(c(0.0), _mm256_max_ps(neg_sigma, c(-SIGMA_CLAMP)));
                // SAFETY: AVX2 is available in this function.
                let e = unsafe { exp_avx2_in_range(x) };
                let a = _mm256_mul_ps(c(s.opacity), e);
                let alpha = _mm256_min_ps(a, c(max_alpha));
                valids[h] = _mm256_and_ps(
                    active,
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_LE_OQ>(neg_sigma, zero),
                        _mm256_cmp_ps::<_CMP_GE_OQ>(alpha, c(ALPHA_THRESHOLD)),
                    ),
                );
                (dxs[h], es[h], as_[h], alphas[h]) = (dx, e, a, alpha);
            }
            let blends = [_mm256_movemask_ps(valids[0]), _mm256_movemask_ps(valids[1])];
            if blends[0] | blends[1] == 0 {
                continue;
            }
            let mut cv = [[zero; 2]; NC];
            for h in 0..2 {
                if blends[h] == 0 {
                    continue;
                }
                let (dx, e, a, alpha, valid) = (dxs[h], es[h], as_[h], alphas[h], valids[h]);
                let one_minus = _mm256_sub_ps(c(1.0), alpha);
                // `max_ps(a, b)` is `a > b ? a : b`: the scalar select with the operands so.
                let den = _mm256_max_ps(one_minus, c(RECOVER_EPS));
                let ra = _mm256_div_ps(c(1.0), den);
                let t = ld(&st.t, h);
                let tn = _mm256_mul_ps(t, ra);
                let fac = _mm256_mul_ps(alpha, tn);
                let sel = |m: __m256, x: __m256| _mm256_and_ps(m, x);
                let v = [ld(&st.v[0], h), ld(&st.v[1], h), ld(&st.v[2], h)];
                for k in 0..3 {
                    cv[k][h] = sel(valid, _mm256_mul_ps(fac, v[k]));
                }
                if GEOMETRY {
                    let term = |col: f32, b: __m256, vv: __m256| {
                        _mm256_mul_ps(
                            _mm256_sub_ps(_mm256_mul_ps(c(col), tn), _mm256_mul_ps(b, ra)),
                            vv,
                        )
                    };
                    let buf = [ld(&st.buf[0], h), ld(&st.buf[1], h), ld(&st.buf[2], h)];
                    let (bz, vd) = (ld(&st.buf_z, h), ld(&st.v_d, h));
                    let mut v_a = term(s.color[0], buf[0], v[0]);
                    v_a = _mm256_add_ps(v_a, term(s.color[1], buf[1], v[1]));
                    v_a = _mm256_add_ps(v_a, term(s.color[2], buf[2], v[2]));
                    v_a = _mm256_add_ps(v_a, term(s.depth, bz, vd));
                    let tfra = _mm256_mul_ps(ld(&st.t_final, h), ra);
                    v_a = _mm256_add_ps(v_a, _mm256_mul_ps(tfra, ld(&st.v_alpha, h)));
                    v_a = _mm256_sub_ps(v_a, _mm256_mul_ps(tfra, ld(&st.bg_dot, h)));
                    cv[3][h] = sel(valid, _mm256_mul_ps(fac, vd));
                    let open = _mm256_and_ps(valid, _mm256_cmp_ps::<_CMP_LE_OQ>(a, c(max_alpha)));
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
                        let nb = _mm256_add_ps(buf[k], _mm256_mul_ps(c(s.color[k]), fac));
                        st_(&mut st.buf[k], h, _mm256_blendv_ps(buf[k], nb, valid));
                    }
                    let nz = _mm256_add_ps(bz, _mm256_mul_ps(c(s.depth), fac));
                    st_(&mut st.buf_z, h, _mm256_blendv_ps(bz, nz, valid));
                }
                st_(&mut st.t, h, _mm256_blendv_ps(t, tn, valid));
            }
            // `add_pairs`: lane j + lane j+8, then into the entry's accumulator.
            for k in 0..fields(GEOMETRY) {
                let p = acc[k].as_mut_ptr();
                // SAFETY: `a[k]` holds 8 f32.
                unsafe {
                    let sum = _mm256_add_ps(_mm256_loadu_ps(p), _mm256_add_ps(cv[k][0], cv[k][1]));
                    _mm256_storeu_ps(p, sum);
                }
            }
        }
    }
}

/// [`avx2::entry`] with AVX-512F intrinsics: one 16-lane register per tile row, masks in mask
/// registers, the same operations one for one. A visit evaluates the whole row when either
/// half is needed; the lanes of a half the AVX2 kernel would not evaluate are masked out of
/// `valid` (so they contribute +0.0 and move no state, exactly as there). Each contribution
/// is reduced as [`add_pairs`]: its upper 8 lanes added to its lower 8 (`c_j + c_{j+8}`),
/// then added into the entry's accumulator.
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{
        ALPHA_THRESHOLD, Acc, EVEN_BITS, Entry, LANES, NC, RECOVER_EPS, RowState, SIGMA_CLAMP,
        fields,
    };
    use crate::math::fastexp::exp_avx512_in_range;
    use std::arch::x86_64::*;

    /// One entry (a splat of the tile's list) walked over the rows its record asks for,
    /// rows ascending, each row's state loaded from and stored back to `states` (each row
    /// sees its splats back to front when the caller walks the entries so), the entry's
    /// accumulators in registers until they are written to `acc`.
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[target_feature(enable = "avx512f")]
    #[allow(clippy::needless_range_loop)] // k indexes parallel register arrays
    pub(super) unsafe fn entry<const GEOMETRY: bool>(
        max_alpha: f32,
        e: &Entry,
        px: &[f32; LANES],
        y0: usize,
        states: &mut [RowState; LANES],
        acc: &mut Acc,
    ) {
        let c = |x: f32| _mm512_set1_ps(x);
        let zero = _mm512_setzero_ps();
        let neg = |x: __m512| {
            let m = _mm512_set1_epi32(i32::MIN);
            _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(x), m))
        };
        let ld = |a: &[f32; LANES]| -> __m512 {
            // SAFETY: `a` holds exactly LANES = 16 f32.
            unsafe { _mm512_loadu_ps(a.as_ptr()) }
        };
        let st_ = |a: &mut [f32; LANES], x: __m512| {
            // SAFETY: `a` holds exactly LANES = 16 f32.
            unsafe { _mm512_storeu_ps(a.as_mut_ptr(), x) }
        };
        const HALF_LANES: [__mmask16; 4] = [0, 0x00ff, 0xff00, 0xffff];
        let Entry { s, pos, halves } = *e;
        let pxv = ld(px);
        let posv = _mm512_set1_epi32(pos as i32);
        let (mx, c0, c1, c2, op) = (
            c(s.mean[0]),
            c(s.conic[0]),
            c(s.conic[1]),
            c(s.conic[2]),
            c(s.opacity),
        );
        let dx = _mm512_sub_ps(mx, pxv);
        let c0dxdx = _mm512_mul_ps(_mm512_mul_ps(c0, dx), dx);
        let c1dx = _mm512_mul_ps(c1, dx);
        let mut a8 = [_mm256_setzero_ps(); NC];
        let mut keep = (halves | halves >> 1) & EVEN_BITS;
        while keep != 0 {
            let b = keep.trailing_zeros();
            keep &= keep - 1;
            let row = b as usize / 2;
            let st = &mut states[row];
            let py = (y0 + row) as f32 + 0.5;
            let dy = s.mean[1] - py;
            let cdd = c(s.conic[2] * dy * dy);
            let dyv = c(dy);
            // SAFETY: `st.n` holds exactly 16 u32.
            let n = unsafe { _mm512_loadu_si512(st.n.as_ptr().cast()) };
            let active =
                _mm512_mask_cmpgt_epi32_mask(HALF_LANES[(halves >> b & 0b11) as usize], n, posv);
            let sum = _mm512_add_ps(c0dxdx, cdd);
            let neg_sigma = _mm512_sub_ps(_mm512_mul_ps(c(-0.5), sum), _mm512_mul_ps(c1dx, dyv));
            // SAFETY: AVX-512F is available in this function.
            let ev = unsafe { exp_avx512_in_range(_mm512_max_ps(neg_sigma, c(-SIGMA_CLAMP))) };
            let a = _mm512_mul_ps(op, ev);
            let alpha = _mm512_min_ps(a, c(max_alpha));
            let valid = _mm512_mask_cmp_ps_mask::<_CMP_GE_OQ>(
                _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(active, neg_sigma, zero),
                alpha,
                c(ALPHA_THRESHOLD),
            );
            let mut cv = [zero; NC];
            let one_minus = _mm512_sub_ps(c(1.0), alpha);
            let den = _mm512_max_ps(one_minus, c(RECOVER_EPS));
            let ra = _mm512_div_ps(c(1.0), den);
            let t = ld(&st.t);
            let tn = _mm512_mul_ps(t, ra);
            let fac = _mm512_mul_ps(alpha, tn);
            let sel = |m: __mmask16, x: __m512| _mm512_maskz_mov_ps(m, x);
            let v = [ld(&st.v[0]), ld(&st.v[1]), ld(&st.v[2])];
            for k in 0..3 {
                cv[k] = sel(valid, _mm512_mul_ps(fac, v[k]));
            }
            if GEOMETRY {
                let buf = [ld(&st.buf[0]), ld(&st.buf[1]), ld(&st.buf[2])];
                let bz = ld(&st.buf_z);
                let vd = ld(&st.v_d);
                let term = |col: f32, b: __m512, vv: __m512| {
                    _mm512_mul_ps(
                        _mm512_sub_ps(_mm512_mul_ps(c(col), tn), _mm512_mul_ps(b, ra)),
                        vv,
                    )
                };
                let mut v_a = term(s.color[0], buf[0], v[0]);
                v_a = _mm512_add_ps(v_a, term(s.color[1], buf[1], v[1]));
                v_a = _mm512_add_ps(v_a, term(s.color[2], buf[2], v[2]));
                v_a = _mm512_add_ps(v_a, term(s.depth, bz, vd));
                let tfra = _mm512_mul_ps(ld(&st.t_final), ra);
                v_a = _mm512_add_ps(v_a, _mm512_mul_ps(tfra, ld(&st.v_alpha)));
                v_a = _mm512_sub_ps(v_a, _mm512_mul_ps(tfra, ld(&st.bg_dot)));
                cv[3] = sel(valid, _mm512_mul_ps(fac, vd));
                let open = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(valid, a, c(max_alpha));
                let v_sigma = _mm512_mul_ps(neg(a), v_a);
                cv[4] = sel(
                    open,
                    _mm512_mul_ps(_mm512_mul_ps(_mm512_mul_ps(c(0.5), v_sigma), dx), dx),
                );
                cv[5] = sel(open, _mm512_mul_ps(_mm512_mul_ps(v_sigma, dx), dyv));
                cv[6] = sel(
                    open,
                    _mm512_mul_ps(_mm512_mul_ps(_mm512_mul_ps(c(0.5), v_sigma), dyv), dyv),
                );
                let gx = _mm512_add_ps(_mm512_mul_ps(c0, dx), _mm512_mul_ps(c1, dyv));
                let gy = _mm512_add_ps(c1dx, _mm512_mul_ps(c2, dyv));
                cv[7] = sel(open, _mm512_mul_ps(v_sigma, gx));
                cv[8] = sel(open, _mm512_mul_ps(v_sigma, gy));
                cv[9] = sel(open, _mm512_mul_ps(ev, v_a));
                for k in 0..3 {
                    let nb = _mm512_add_ps(buf[k], _mm512_mul_ps(c(s.color[k]), fac));
                    st_(&mut st.buf[k], _mm512_mask_blend_ps(valid, buf[k], nb));
                }
                let nz = _mm512_add_ps(bz, _mm512_mul_ps(c(s.depth), fac));
                st_(&mut st.buf_z, _mm512_mask_blend_ps(valid, bz, nz));
            }
            st_(&mut st.t, _mm512_mask_blend_ps(valid, t, tn));
            for k in 0..fields(GEOMETRY) {
                let lo = _mm512_castps512_ps256(cv[k]);
                let hi = _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(cv[k])));
                a8[k] = _mm256_add_ps(a8[k], _mm256_add_ps(lo, hi));
            }
        }
        for k in 0..NC {
            // SAFETY: `acc[k]` holds 8 f32.
            unsafe { _mm256_storeu_ps(acc[k].as_mut_ptr(), a8[k]) };
        }
    }
}

/// The backward of tiles `tiles` (flat indices, row-major) into `out`, in tile order.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn tiles<const ISA: u8, const GEOMETRY: bool>(
    tiles: std::ops::Range<usize>,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    cull_rows: bool,
    max_alpha: f32,
    background: [f32; 3],
    g: &PixelGrads,
) -> TileGrads {
    // At most one entry per intersection of the run: the outputs never grow by copying.
    let most = bins.offsets[tiles.end] - bins.offsets[tiles.start];
    let mut out = TileGrads {
        gids: Vec::with_capacity(most),
        grads: Vec::with_capacity(most),
        starts: Vec::with_capacity(tiles.len() * (sum_buckets(p.splats.len()).1 + 1)),
        pairs: 0,
        walked: 0,
    };
    // The thread's work area, reused by every tile and run it blends: no allocation (nor
    // the page faults of fresh memory) once it has grown to the largest tile. Taken out
    // and put back rather than used inside `with`: a closure would compile the list
    // building without the caller's target features.
    let mut scratch = SCRATCH.with_borrow_mut(std::mem::take);
    tiles_with::<ISA, GEOMETRY>(
        tiles,
        width,
        height,
        p,
        bins,
        cull_rows,
        max_alpha,
        background,
        g,
        &mut scratch,
        &mut out,
    );
    SCRATCH.with_borrow_mut(|s| *s = scratch);
    out
}

/// Per-thread work area of [`tiles`].
#[derive(Default)]
struct Scratch {
    list: Vec<Entry>,
    gids: Vec<u32>,
    /// Per entry of the tile, its place among the tile's entries grouped by bucket.
    place: Vec<u32>,
    /// Per bucket, the next place (a counting sort's counters).
    counts: Vec<u32>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::default();
}

/// [`tiles`] in a given work area.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn tiles_with<const ISA: u8, const GEOMETRY: bool>(
    tiles: std::ops::Range<usize>,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    cull_rows: bool,
    max_alpha: f32,
    background: [f32; 3],
    g: &PixelGrads,
    scratch: &mut Scratch,
    out: &mut TileGrads,
) {
    let Scratch {
        list,
        gids,
        place,
        counts,
    } = scratch;
    let (shift, buckets) = sum_buckets(p.splats.len());
    let mut states = [RowState::default(); TILE_SIZE];
    for t in tiles {
        let (ty, tx) = (t / bins.tiles_x, t % bins.tiles_x);
        let y0 = ty * TILE_SIZE;
        let rows = TILE_SIZE.min(height - y0);
        let x0 = tx * TILE_SIZE;
        let cols = TILE_SIZE.min(width - x0);
        let ids = bins.tile(t);
        // Each row's backward state, and the prefix of the list it walks (the largest
        // `n_contrib` of its pixels).
        let mut row_n = [0u32; TILE_SIZE];
        for row in 0..rows {
            let st = &mut states[row];
            *st = RowState::default();
            for l in 0..cols {
                let i = (y0 + row) * width + x0 + l;
                let (tf, v_rgb, v_alpha, v_d) = upstream(g, i);
                st.t[l] = tf;
                st.t_final[l] = tf;
                for (k, &v) in v_rgb.iter().enumerate() {
                    st.v[k][l] = v;
                }
                st.v_alpha[l] = v_alpha;
                st.v_d[l] = v_d;
                st.bg_dot[l] = (background[0] * v_rgb[0] + background[1] * v_rgb[1])
                    + background[2] * v_rgb[2];
                st.n[l] = g.n_contrib[i];
            }
            row_n[row] = st.n.iter().copied().max().unwrap_or(0);
        }
        // Only the prefix some pixel blended is needed, and of it only the splats some row
        // walks: those that can reach the row and lie before its last blended splat, each
        // with the (row, half) visits it gets.
        let max_n = row_n.iter().copied().max().unwrap_or(0) as usize;
        let prefix = &ids[..max_n];
        let off = bins.offsets[t];
        list.clear();
        gids.clear();
        // The rows still before their last blended splat at `pos` (bit `row`: `pos < n`),
        // renewed when `pos` reaches the smallest `n` among them.
        let (mut alive, mut next) = (0u32, 0u32);
        for (pos, &gid) in prefix.iter().enumerate() {
            // The gather is bound by cache misses on the splats in list order: ask early.
            #[cfg(target_arch = "x86_64")]
            if let Some(&ahead) = prefix.get(pos + PREFETCH) {
                use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
                let a = ahead as usize;
                // SAFETY: prefetching never faults; the indices are in bounds.
                unsafe {
                    // A splat (40 bytes) may straddle two cache lines: ask for both ends.
                    let sp = p.splats.as_ptr().add(a) as *const i8;
                    _mm_prefetch::<_MM_HINT_T0>(sp);
                    _mm_prefetch::<_MM_HINT_T0>(sp.add(size_of::<Splat>() - 1));
                    _mm_prefetch::<_MM_HINT_T0>(p.radii.as_ptr().add(a) as *const i8);
                }
            }
            let (lo, hi) = splat_rows(p, gid as usize, y0, rows, cull_rows);
            // The rows whose visit is counted: within the splat's reach and before the row's
            // last blended splat (the work unit counts every such visit, skipped or not, the
            // same count for every kernel and plan).
            let pos32 = pos as u32;
            if pos32 >= next {
                (alive, next) = (0, u32::MAX);
                for (row, &n) in row_n.iter().enumerate() {
                    if pos32 < n {
                        alive |= 1 << row;
                        next = next.min(n);
                    }
                }
            }
            // lo ≤ hi ≤ 16: bits lo..hi.
            let within_n = ((1u32 << hi) - (1u32 << lo)) & alive;
            out.pairs += u64::from(within_n.count_ones()) * LANES as u64;
            // The visits kept, as (row, halves) pairs in bits `2·row + h`: with culling the
            // row halves where the forward blended this splat (a lane the forward did not
            // blend contributes +0.0 and moves no state), else every counted row, whole.
            let halves = if cull_rows {
                g.blend_halves[off + pos]
            } else {
                spread_rows(within_n) * 0b11
            };
            let keep = (halves | halves >> 1) & EVEN_BITS;
            if keep == 0 {
                continue;
            }
            out.walked += u64::from(keep.count_ones()) * LANES as u64;
            list.push(Entry {
                s: p.splats[gid as usize],
                pos: pos32,
                halves,
            });
            gids.push(gid);
        }
        let mut px = [0f32; LANES];
        for (l, v) in px.iter_mut().enumerate() {
            *v = (x0 + l) as f32 + 0.5;
        }
        // Each entry's place among the tile's entries grouped by bucket, list order kept
        // within a bucket (a stable counting sort), and the buckets' starts.
        let first = out.gids.len();
        counts.clear();
        counts.resize(buckets + 1, 0);
        for &gid in gids.iter() {
            counts[(gid >> shift) as usize + 1] += 1;
        }
        // `counts[b + 1]` holds bucket b's count: the inclusive prefix sum is the starts.
        let mut at = first as u32;
        for c in counts.iter_mut() {
            at += *c;
            *c = at;
        }
        out.starts.extend_from_slice(counts);
        place.clear();
        out.gids.resize(first + gids.len(), 0);
        for &gid in gids.iter() {
            let k = &mut counts[(gid >> shift) as usize];
            place.push(*k);
            out.gids[*k as usize] = gid;
            *k += 1;
        }
        // Entries back to front, so that each row meets its splats back to front; each
        // entry's gradient goes to its place.
        out.grads.resize(first + list.len(), SplatGrad::default());
        let mut acc: Acc = [[0.0; HALF]; NC];
        for (e, &k) in list.iter().zip(place.iter()).rev() {
            walk::<ISA, GEOMETRY>(max_alpha, e, &px, y0, &mut states, &mut acc);
            out.grads[k as usize] = reduce_isa::<ISA, GEOMETRY>(&acc);
        }
    }
}

/// One entry walked by the kernel of `ISA` ([`entry_lanes`] and its vector forms).
#[inline(always)]
fn walk<const ISA: u8, const GEOMETRY: bool>(
    max_alpha: f32,
    e: &Entry,
    px: &[f32; LANES],
    y0: usize,
    states: &mut [RowState; LANES],
    acc: &mut Acc,
) {
    #[cfg(target_arch = "x86_64")]
    if ISA == ISA_AVX512 {
        // SAFETY: ISA_AVX512 only when the CPU has AVX-512F (checked by the caller).
        unsafe { avx512::entry::<GEOMETRY>(max_alpha, e, px, y0, states, acc) }
    } else if ISA == ISA_AVX2 {
        // SAFETY: ISA_AVX2 only when the CPU has AVX2 (checked by the caller).
        unsafe { avx2::entry::<GEOMETRY>(max_alpha, e, px, y0, states, acc) }
    } else {
        entry_lanes::<GEOMETRY>(max_alpha, e, px, y0, states, acc)
    }
    #[cfg(not(target_arch = "x86_64"))]
    entry_lanes::<GEOMETRY>(max_alpha, e, px, y0, states, acc);
}

/// [`reduce`] in the form compiled for `ISA` (the same bits).
#[inline(always)]
fn reduce_isa<const ISA: u8, const GEOMETRY: bool>(acc: &Acc) -> SplatGrad {
    #[cfg(target_arch = "x86_64")]
    if ISA != ISA_SCALAR {
        return reduce_lanes::<GEOMETRY>(acc);
    }
    reduce::<GEOMETRY>(acc)
}

/// [`tiles`] compiled for AVX-512F (its list building too, not only the entry kernel).
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn tiles_avx512<const GEOMETRY: bool>(
    run: std::ops::Range<usize>,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    cull_rows: bool,
    max_alpha: f32,
    background: [f32; 3],
    g: &PixelGrads,
) -> TileGrads {
    tiles::<ISA_AVX512, GEOMETRY>(
        run, width, height, p, bins, cull_rows, max_alpha, background, g,
    )
}

/// [`tiles`] compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn tiles_avx2<const GEOMETRY: bool>(
    run: std::ops::Range<usize>,
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    cull_rows: bool,
    max_alpha: f32,
    background: [f32; 3],
    g: &PixelGrads,
) -> TileGrads {
    tiles::<ISA_AVX2, GEOMETRY>(
        run, width, height, p, bins, cull_rows, max_alpha, background, g,
    )
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

/// The background's gradient `Σ_pixels T_final·v_rgb`, summed in f64 per band of tile rows
/// (tiles in order, each tile's rows, each row's columns), the bands' sums added in order.
fn background_grad(width: usize, height: usize, bins: &TileBins, g: &PixelGrads) -> [f64; 3] {
    let Some(v_rgb) = g.v_rgb else {
        return [0.0; 3];
    };
    let band = |ty: usize| {
        let mut bg = [0f64; 3];
        let y0 = ty * TILE_SIZE;
        for tx in 0..bins.tiles_x {
            let x0 = tx * TILE_SIZE;
            for y in y0..(y0 + TILE_SIZE).min(height) {
                for x in x0..(x0 + TILE_SIZE).min(width) {
                    let i = y * width + x;
                    for (k, b) in bg.iter_mut().enumerate() {
                        *b += (g.final_t[i] * v_rgb[3 * i + k]) as f64;
                    }
                }
            }
        }
        bg
    };
    let bands: Vec<[f64; 3]> = (0..bins.tiles_y).into_par_iter().map(band).collect();
    let mut bg = [0f64; 3];
    for b in bands {
        for (acc, v) in bg.iter_mut().zip(b) {
            *acc += v;
        }
    }
    bg
}

/// Backward of [`crate::raster::composite::composite`]: per-Gaussian splat gradients.
#[allow(clippy::too_many_arguments)]
pub fn composite_backward(
    width: usize,
    height: usize,
    p: &Projected,
    bins: &TileBins,
    cull_rows: bool,
    max_alpha: f32,
    background: [f32; 3],
    g: &PixelGrads,
    geometry: bool,
    kernel: Kernel,
) -> CompositeGrads {
    let isa = if kernel.avx512() {
        ISA_AVX512
    } else if kernel.avx2() {
        ISA_AVX2
    } else {
        ISA_SCALAR
    };
    let (w, h, bkg, ma) = (width, height, background, max_alpha);
    let run = |r: std::ops::Range<usize>| match (isa, geometry) {
        // SAFETY: ISA_AVX512 only when the CPU has AVX-512F (`Kernel::avx512` checked it).
        #[cfg(target_arch = "x86_64")]
        (ISA_AVX512, true) => unsafe {
            tiles_avx512::<true>(r, w, h, p, bins, cull_rows, ma, bkg, g)
        },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        (ISA_AVX512, false) => unsafe {
            tiles_avx512::<false>(r, w, h, p, bins, cull_rows, ma, bkg, g)
        },
        // SAFETY: ISA_AVX2 only when the CPU has AVX2 (`Kernel::avx2` checked it).
        #[cfg(target_arch = "x86_64")]
        (ISA_AVX2, true) => unsafe { tiles_avx2::<true>(r, w, h, p, bins, cull_rows, ma, bkg, g) },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        (ISA_AVX2, false) => unsafe {
            tiles_avx2::<false>(r, w, h, p, bins, cull_rows, ma, bkg, g)
        },
        (_, true) => tiles::<ISA_SCALAR, true>(r, w, h, p, bins, cull_rows, ma, bkg, g),
        (_, false) => tiles::<ISA_SCALAR, false>(r, w, h, p, bins, cull_rows, ma, bkg, g),
    };
    let n_tiles = bins.tiles_x * bins.tiles_y;
    let per = n_tiles.div_ceil(MAX_TASKS).max(1);
    let parts: Vec<TileGrads> = longest_first(&bins.run_costs(per, height), |k| {
        run(k * per..((k + 1) * per).min(n_tiles))
    });
    // Sum per Gaussian in tile order. Only walked intersections are listed: the others
    // would add +0.0 to accumulators that are never −0.0. Buckets of Gaussians in
    // parallel, each zeroed and then given its entries from every tile in order (and
    // within a tile in list order): each Gaussian gets its additions in tile order
    // whatever thread sums its bucket, so the bits do not depend on the partition.
    let n = p.splats.len();
    let (shift, buckets) = sum_buckets(n);
    let mut splats: Vec<SplatGrad> = Vec::with_capacity(n);
    splats.spare_capacity_mut()[..n]
        .par_chunks_mut(1 << shift)
        .enumerate()
        .for_each(|(b, out)| {
            out.fill(std::mem::MaybeUninit::new(SplatGrad::default()));
            // SAFETY: every element of `out` was just initialized, and `MaybeUninit<T>`
            // has `T`'s layout.
            let out = unsafe {
                &mut *(out as *mut [std::mem::MaybeUninit<SplatGrad>] as *mut [SplatGrad])
            };
            let lo = b << shift;
            for part in &parts {
                for tile in part.starts.chunks_exact(buckets + 1) {
                    let range = tile[b] as usize..tile[b + 1] as usize;
                    for (&gid, gr) in part.gids[range.clone()].iter().zip(&part.grads[range]) {
                        out[gid as usize - lo].add(gr);
                    }
                }
            }
        });
    // SAFETY: the chunks cover the first `n` elements, each initialized above.
    unsafe { splats.set_len(n) };
    let pairs = parts.iter().map(|b| b.pairs).sum();
    let walked = parts.iter().map(|b| b.walked).sum();
    let bg = background_grad(width, height, bins, g);
    CompositeGrads {
        splats,
        background: bg.map(|v| v as f32),
        pairs,
        walked,
    }
}

/// The backward blend kernel alone: the bound [`composite_backward`] is measured against
/// (`benches/roofline.rs`, SPEC.md §5.8), as [`crate::raster::composite::bare_blend`] is the
/// forward's. `rows` tile rows (16 pixels each, in blocks of 16 rows with a fresh state, as a
/// tile's), every splat of `splats` walked back to front over the rows of its block with all
/// ten gradients (the training backward), with the same entry kernel and arithmetic as
/// [`composite_backward`] with culling: a splat visits the (row, half) pairs where some lane
/// blends it (its record, as the forward's), every pixel has the whole list before its last
/// blended splat, the list and its accumulators stay in the cache (at most 256 splats), no
/// list building, no reduction, no per-Gaussian sums. Blocks are split over the rayon pool
/// in fixed runs, each with its own accumulators. Returns the Gaussian-pixel pairs walked
/// (16 per row visit, as [`CompositeGrads::walked`] counts them).
#[doc(hidden)]
pub fn bare_blend_backward(splats: &[Splat], rows: usize, kernel: Kernel) -> u64 {
    assert!(
        splats.len() <= 256,
        "the bare kernel's list must stay in the cache"
    );
    // Each splat's visits as the forward's record would give them: the (row, half) pairs
    // where some lane blends it (σ ≥ 0, α ≥ 1/255; every pixel has the whole list before
    // its last blended splat). The others would add +0.0 and are not walked, as in
    // `composite_backward` with culling.
    let record = |s: &Splat| {
        let mut halves = 0u32;
        for row in 0..TILE_SIZE {
            for l in 0..LANES {
                let (dx, dy) = (s.mean[0] - (l as f32 + 0.5), s.mean[1] - (row as f32 + 0.5));
                let SplatAlpha { sigma, alpha, .. } = splat_alpha(s, dx, dy, BARE_MAX_ALPHA);
                if sigma >= 0.0 && alpha >= ALPHA_THRESHOLD {
                    halves |= 1 << (2 * row + l / HALF);
                }
            }
        }
        halves
    };
    let list: Vec<Entry> = (0..splats.len())
        .map(|k| Entry {
            s: splats[k],
            pos: k as u32,
            halves: record(&splats[k]),
        })
        .filter(|e| e.halves != 0)
        .collect();
    // Runs of whole blocks of 16 rows; the last block of the last run may be shorter.
    let blocks = rows.div_ceil(TILE_SIZE);
    let runs = rayon::current_num_threads().max(1);
    let per = blocks.div_ceil(runs);
    (0..runs)
        .into_par_iter()
        .map(|r| {
            let rows = (((r + 1) * per * TILE_SIZE).min(rows)).saturating_sub(r * per * TILE_SIZE);
            #[cfg(target_arch = "x86_64")]
            if kernel.avx512() {
                // SAFETY: AVX-512F was detected (`Kernel::avx512`).
                unsafe { bare_avx512(&list, rows) };
            } else if kernel.avx2() {
                // SAFETY: AVX2 was detected (`Kernel::avx2`).
                unsafe { bare_avx2(&list, rows) };
            } else {
                bare_rows::<ISA_SCALAR>(&list, rows);
            }
            #[cfg(not(target_arch = "x86_64"))]
            bare_rows::<ISA_SCALAR>(&list, rows);
            // Row visits: a block's rows' bits of every entry, whole blocks and the last.
            let visits = |block: usize| {
                let rows = (1u64 << (2 * block)) - 1;
                list.iter()
                    .map(|e| ((e.halves | e.halves >> 1) & EVEN_BITS) as u64 & rows)
                    .map(|k| u64::from(k.count_ones()))
                    .sum::<u64>()
            };
            let (whole, last) = (rows / TILE_SIZE, rows % TILE_SIZE);
            (whole as u64 * visits(TILE_SIZE) + visits(last)) * LANES as u64
        })
        .sum()
}

/// The α clamp of [`bare_blend_backward`] (the default profile's).
const BARE_MAX_ALPHA: f32 = 0.99;

/// [`bare_blend_backward`]'s walk of `rows` rows, 16 at a time, in the kernel of `ISA`.
#[inline(always)]
fn bare_rows<const ISA: u8>(list: &[Entry], rows: usize) {
    let mut px = [0f32; LANES];
    for (l, v) in px.iter_mut().enumerate() {
        *v = l as f32 + 0.5;
    }
    // A state every splat can blend into and that stays finite over the walk: the
    // transmittance grows by 1/(1 − α) per blended splat (α ≤ 0.06 here).
    let fresh = RowState {
        t: [1e-3; LANES],
        t_final: [1e-3; LANES],
        v: [[0.25; LANES], [-0.5; LANES], [0.125; LANES]],
        v_d: [0.0625; LANES],
        v_alpha: [0.0; LANES],
        bg_dot: [0.0; LANES],
        n: [list.len() as u32; LANES],
        buf: [[0.0; LANES]; 3],
        buf_z: [0.0; LANES],
    };
    let mut acc = vec![[[0f32; HALF]; NC]; list.len()];
    // The last block's entries ask only for its rows.
    let mut short = list.to_vec();
    for y in (0..rows).step_by(TILE_SIZE) {
        let block = TILE_SIZE.min(rows - y);
        let list = if block == TILE_SIZE {
            list
        } else {
            let mask = (1u32 << (2 * block)) - 1;
            short
                .iter_mut()
                .zip(list)
                .for_each(|(s, e)| s.halves = e.halves & mask);
            &short
        };
        let mut states = [fresh; TILE_SIZE];
        for (e, a) in list.iter().zip(&mut acc).rev() {
            walk::<ISA, true>(BARE_MAX_ALPHA, e, &px, 0, &mut states, a);
        }
        std::hint::black_box(&states);
    }
    std::hint::black_box(&acc); // the accumulators are the kernel's only output
}

/// [`bare_rows`] compiled for AVX-512F.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn bare_avx512(list: &[Entry], rows: usize) {
    bare_rows::<ISA_AVX512>(list, rows)
}

/// [`bare_rows`] compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn bare_avx2(list: &[Entry], rows: usize) {
    bare_rows::<ISA_AVX2>(list, rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Buckets of at least 512 Gaussians, at most 256 of them, covering every Gaussian
    /// exactly once, for scenes from empty to past `u32::MAX >> 1` Gaussians.
    #[test]
    fn sum_buckets_cover_the_scene_in_at_most_256_buckets_of_at_least_512() {
        let mut sizes = vec![0usize, 1, 511, 512, 513, 131_071, 131_072, 131_073, 1 << 31];
        sizes.extend((0..40).map(|k| 1usize << (k / 2) | k));
        for n in sizes {
            let (shift, buckets) = sum_buckets(n);
            assert!(shift >= 9, "{n}: buckets of {}", 1usize << shift);
            assert!(buckets <= 256, "{n}: {buckets} buckets");
            // Every Gaussian's bucket exists, and the last one holds a Gaussian.
            match n.checked_sub(1) {
                Some(last) => assert_eq!(last >> shift, buckets - 1, "{n}"),
                None => assert_eq!(buckets, 0),
            }
        }
    }
}
