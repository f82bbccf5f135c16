//! Tile binning: which Gaussians touch which 16×16 tile, each tile's list sorted front to back.
//!
//! A Gaussian with centre `m` and radii `r` touches the tiles
//! `[floor((m−r)/16), ceil((m+r)/16))` in x and y, clamped to the grid (gsplat
//! `intersect_tile`). Lists are ordered by the total order (camera z as IEEE bits, Gaussian
//! index): the visible Gaussians are sorted once by that key (a stable LSD radix sort on the
//! depth bits of records made in index order), then scattered into per-tile lists in that
//! order, so every list is sorted. Every pass runs over fixed chunks (boundaries set by the
//! input size alone) and is an exact counting pass — per-chunk histograms or per-tile
//! counts, prefix sums giving each chunk its own write cursors — so the result is the same
//! bit for bit for any thread count. [`bin_into`] reuses its buffers across frames.
//!
//! The parallel scatters write through a shared pointer to slots the prefix sums make
//! disjoint (`Shared`, bounds-checked); that and the AVX-512F record pass are the
//! `unsafe` here.

use super::kernel::Kernel;
use super::project::{Projected, SPLAT_FLOATS, Splat};
use rayon::prelude::*;

/// Tile edge in pixels (gsplat, INRIA `BLOCK_X = BLOCK_Y = 16`).
pub const TILE_SIZE: usize = 16;

/// Per-tile lists of Gaussian indices, front to back.
#[derive(Clone, Debug, Default)]
pub struct TileBins {
    pub tiles_x: usize,
    pub tiles_y: usize,
    /// `offsets[t]..offsets[t+1]` indexes `ids` for tile `t = ty·tiles_x + tx`.
    pub offsets: Vec<usize>,
    pub ids: Vec<u32>,
}

impl TileBins {
    pub fn tile(&self, t: usize) -> &[u32] {
        &self.ids[self.offsets[t]..self.offsets[t + 1]]
    }
    /// Total (tile, Gaussian) intersections.
    pub fn intersections(&self) -> usize {
        self.ids.len()
    }
    /// The blend's estimated cost of each run of `per` tiles (tiles in order, the last run
    /// possibly shorter) of an image `height` pixels high: Σ intersections × pixel rows,
    /// the pairs the blend would evaluate if no pixel saturated (for
    /// [`crate::raster::schedule::longest_first`]).
    pub(crate) fn run_costs(&self, per: usize, height: usize) -> Vec<u64> {
        let n_tiles = self.tiles_x * self.tiles_y;
        let tile_cost = |t: usize| {
            let rows = TILE_SIZE.min(height - (t / self.tiles_x) * TILE_SIZE);
            ((self.offsets[t + 1] - self.offsets[t]) * rows) as u64
        };
        (0..n_tiles.div_ceil(per))
            .map(|k| (k * per..((k + 1) * per).min(n_tiles)).map(tile_cost).sum())
            .collect()
    }
}

/// The tile rectangle `[x0, x1) × [y0, y1)` of a splat, clamped to the grid.
#[inline]
pub fn tile_rect(mean: [f32; 2], radii: [i32; 2], tiles_x: usize, tiles_y: usize) -> [usize; 4] {
    let t = TILE_SIZE as f32;
    let (rx, ry) = (radii[0] as f32, radii[1] as f32);
    [
        floor_clamped((mean[0] - rx) / t, tiles_x),
        ceil_clamped((mean[0] + rx) / t, tiles_x),
        floor_clamped((mean[1] - ry) / t, tiles_y),
        ceil_clamped((mean[1] + ry) / t, tiles_y),
    ]
}

/// `clamp(floor(v), 0, hi)`, NaN → 0, branch-free: Rust's `f32 as i64` truncates toward
/// zero, saturates and maps NaN to 0, so for `v > 0` it is the floor, and a `v ≤ 0` gives
/// at most 0.
#[inline(always)]
fn floor_clamped(v: f32, hi: usize) -> usize {
    ((v as i64).max(0) as usize).min(hi)
}

/// `clamp(ceil(v), 0, hi)`, NaN → 0, branch-free: the truncation `t`, plus 1 where `t < v`
/// (`t as f32` is exact wherever that can hold: `|v| < 2^24`; above, `v` is an integer and
/// `t = v`, or `t` is saturated — at +∞ the sum saturates too).
#[inline(always)]
fn ceil_clamped(v: f32, hi: usize) -> usize {
    let t = v as i64;
    (t.saturating_add(((t as f32) < v) as i64).max(0) as usize).min(hi)
}

/// Bin the visible splats (radii not both 0) of an image `width × height`. `kernel`
/// chooses the record pass's form (sixteen splats per AVX-512F instruction with
/// `Kernel::Auto` where the CPU has it, else one at a time); both give the same lists.
///
/// Allocates its result and work area; [`bin_into`] reuses both across frames.
pub fn bin(p: &Projected, width: usize, height: usize, kernel: Kernel) -> TileBins {
    let mut out = TileBins::default();
    bin_into(
        p,
        width,
        height,
        kernel,
        &mut BinScratch::default(),
        &mut out,
    );
    out
}

/// Smallest chunk of every parallel pass. Chunk boundaries depend only on the input size,
/// never on the thread count (the result does not depend on them either: every pass is an
/// exact counting pass). Small enough that the pipeline's scenes at 80×60 (15–35k visible
/// splats) make ten or more chunks to share between threads (8 192 made four or five).
const CHUNK: usize = 2048;
/// Most chunks of the sort and the scatter (bounds their per-chunk counters: histograms,
/// per-tile cursors).
const MAX_CHUNKS: usize = 32;

/// Chunk length for `n` items: at least [`CHUNK`], at most [`MAX_CHUNKS`] chunks.
fn chunk_len(n: usize) -> usize {
    CHUNK.max(n.div_ceil(MAX_CHUNKS))
}
/// Widest radix digit (2048 buckets: the per-chunk histograms stay in L1).
const MAX_DIGIT_BITS: u32 = 11;

/// Reusable work area of [`bin_into`]: the buffers grow to the largest frame seen and are
/// not freed between frames.
#[derive(Clone, Debug, Default)]
pub struct BinScratch {
    /// One record per visible splat, `[depth_bits << 32 | index, packed tile rectangle]`,
    /// and the radix sort's second buffer.
    recs: Vec<[u64; 2]>,
    recs_tmp: Vec<[u64; 2]>,
    /// Per chunk of Gaussians: the smallest and largest depth bits of its visible splats and
    /// their count.
    chunks: Vec<(u32, u32, usize)>,
    /// Per-chunk counters (visible splats, radix histograms, per-tile counts), turned into
    /// write cursors in place.
    counts: Vec<usize>,
    /// One counter per digit or grid cell: the running sums of [`cursors`].
    running: Vec<usize>,
}

/// A tile rectangle packed into a u64: `x0 | x1 << bx | y0 << 2bx | y1 << (2bx + by)`.
#[derive(Clone, Copy, Debug)]
struct Packing {
    bx: u32,
    by: u32,
}

impl Packing {
    fn new(tiles_x: usize, tiles_y: usize) -> Self {
        let bx = usize::BITS - tiles_x.leading_zeros();
        let by = usize::BITS - tiles_y.leading_zeros();
        // Fails only for grids of more than ~2^30 tiles (2^38 pixels).
        assert!(
            2 * (bx + by) <= 63,
            "tile grid {tiles_x}×{tiles_y} too large"
        );
        Packing { bx, by }
    }
    #[inline(always)]
    fn pack(self, r: [usize; 4]) -> u64 {
        let [x0, x1, y0, y1] = r.map(|v| v as u64);
        x0 | x1 << self.bx | y0 << (2 * self.bx) | y1 << (2 * self.bx + self.by)
    }
    #[inline(always)]
    fn unpack(self, v: u64) -> [usize; 4] {
        let (mx, my) = ((1u64 << self.bx) - 1, (1u64 << self.by) - 1);
        [
            (v & mx) as usize,
            (v >> self.bx & mx) as usize,
            (v >> (2 * self.bx) & my) as usize,
            (v >> (2 * self.bx + self.by) & my) as usize,
        ]
    }
}

/// [`bin`] into `out`, reusing `out`'s and `scratch`'s buffers (no allocation once they
/// are large enough).
///
/// 1. Per fixed chunk of Gaussians (parallel): a record per visible splat, in index order
///    at the chunk's head (`depth_bits << 32 | index`, its packed tile rectangle; sixteen
///    splats per AVX-512F instruction where the CPU has it, compressed to the head: the same
///    records), the minimum and maximum depth bits and the count of the visible ones; then
///    the chunks' records gathered in order (parallel copies at running-sum offsets).
///    Culled splats never reach the sort (at 80×60 about 60 % of a trained scene is culled).
/// 2. Stable LSD radix sort of the visible records on `depth_bits − min` (only the bits
///    the range needs: `⌈bits/11⌉` passes of equal width ≤ 11 bits). Each pass: per-chunk
///    histograms (parallel), an exclusive prefix sum in (digit, chunk) order giving each
///    chunk its write cursor per digit, a parallel scatter. Stability over index-ordered
///    input makes the order (depth bits, Gaussian index).
/// 3. Per fixed chunk of the sorted records (parallel): count per tile (branch-free, on a
///    grid of 2D differences); an exclusive prefix sum in (tile, chunk) order gives the
///    tile offsets and each chunk's write cursor per tile; a parallel scatter writes each
///    tile's list in sorted order.
pub fn bin_into(
    p: &Projected,
    width: usize,
    height: usize,
    kernel: Kernel,
    scratch: &mut BinScratch,
    out: &mut TileBins,
) {
    let tiles_x = width.div_ceil(TILE_SIZE);
    let tiles_y = height.div_ceil(TILE_SIZE);
    let n_tiles = tiles_x * tiles_y;
    out.tiles_x = tiles_x;
    out.tiles_y = tiles_y;
    resize(&mut out.offsets, n_tiles + 1);
    if n_tiles == 0 {
        out.offsets[0] = 0;
        out.ids.clear();
        return;
    }
    let BinScratch {
        recs,
        recs_tmp,
        chunks,
        counts,
        running,
    } = scratch;
    assert!(
        p.radii.len() <= u32::MAX as usize,
        "more Gaussians than u32 indices"
    );
    let packing = Packing::new(tiles_x, tiles_y);

    // 1. Per chunk of Gaussians, a record per visible one in index order at the chunk's
    // head; then the chunks' records gathered, in order.
    assert_eq!(
        p.splats.len(),
        p.radii.len(),
        "splats and radii differ in length"
    );
    let n_all = p.radii.len();
    resize(recs, n_all);
    #[cfg(target_arch = "x86_64")]
    let (avx512, avx2) = (kernel.avx512(), kernel.avx2());
    #[cfg(not(target_arch = "x86_64"))]
    let _ = kernel;
    recs.par_chunks_mut(CHUNK)
        .zip(p.radii.par_chunks(CHUNK).zip(p.splats.par_chunks(CHUNK)))
        .enumerate()
        .map(|(c, (out, (radii, splats)))| {
            let grid = (packing, tiles_x, tiles_y);
            #[cfg(target_arch = "x86_64")]
            if avx512 {
                // SAFETY: AVX-512F was detected (`Kernel::avx512`).
                return unsafe { records_avx512(splats, radii, c * CHUNK, grid, out) };
            }
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: AVX2 was detected (`Kernel::avx2`).
                return unsafe { records_avx2(splats, radii, c * CHUNK, grid, out) };
            }
            records(splats, radii, c * CHUNK, grid, out)
        })
        .collect_into_vec(chunks);
    let (mut min, mut max, mut n) = (u32::MAX, 0, 0);
    for &(lo, hi, count) in chunks.iter() {
        (min, max, n) = (min.min(lo), max.max(hi), n + count);
    }
    // The gather, into the sort's second buffer (the buffers keep their lengths: refilling
    // a tail cut off would cost a memset of the culled records' share every frame).
    resize(recs_tmp, n_all);
    counts.clear();
    counts.extend(chunks.iter().scan(0, |at, c| {
        let start = *at;
        *at += c.2;
        Some(start)
    }));
    let dst = Shared::new(recs_tmp);
    recs.par_chunks(CHUNK)
        .zip(chunks.par_iter())
        .zip(counts.par_iter())
        .for_each(|((src, c), &start)| {
            // SAFETY: chunk `c` writes `start..start + count`, ranges disjoint across
            // chunks by the running sum, all `≤ n ≤ n_all`, the buffer's length.
            unsafe { dst.write_slice(start, &src[..c.2]) };
        });
    std::mem::swap(recs, recs_tmp);

    // 2. Sort by (depth bits, Gaussian index).
    let bits = if n > 1 {
        32 - (max - min).leading_zeros()
    } else {
        0
    };
    radix_sort(recs, recs_tmp, (counts, running), min, bits, n);
    let recs = &recs[..n];

    // 3. Per-tile counts per chunk of the sorted records, then the scatter. The counts
    // are taken branch-free on a (tiles_x + 1) × (tiles_y + 1) grid of 2D differences
    // (+1 at (x0, y0) and (x1, y1), −1 at (x1, y0) and (x0, y1), in wrapping arithmetic),
    // integrated along rows then columns: cell (tx, ty) then holds the count of tile t.
    let (gx, gy) = (tiles_x + 1, tiles_y + 1);
    let grid = gx * gy;
    let len = chunk_len(n);
    let n_chunks = n.div_ceil(len);
    reset(counts, n_chunks * grid);
    recs.par_chunks(len)
        .zip(counts.par_chunks_mut(grid))
        .for_each(|(chunk, d)| {
            for rec in chunk {
                let [x0, x1, y0, y1] = packing.unpack(rec[1]);
                d[y0 * gx + x0] = d[y0 * gx + x0].wrapping_add(1);
                d[y0 * gx + x1] = d[y0 * gx + x1].wrapping_sub(1);
                d[y1 * gx + x0] = d[y1 * gx + x0].wrapping_sub(1);
                d[y1 * gx + x1] = d[y1 * gx + x1].wrapping_add(1);
            }
            for row in d.chunks_exact_mut(gx) {
                for x in 1..gx {
                    row[x] = row[x].wrapping_add(row[x - 1]);
                }
            }
            for y in 1..gy {
                let (above, row) = d[(y - 1) * gx..(y + 1) * gx].split_at_mut(gx);
                for (v, a) in row.iter_mut().zip(above.iter()) {
                    *v = v.wrapping_add(*a);
                }
            }
        });
    // Exclusive prefix sum in (tile, chunk) order: tile offsets and chunk cursors (cells
    // off the tile grid, the last column and row, get cursors no record uses).
    let tile_offsets = (0..tiles_y).flat_map(|ty| (0..tiles_x).map(move |tx| ty * gx + tx));
    let acc = cursors(counts, grid, running, tile_offsets, |t, at| {
        out.offsets[t] = at
    });
    out.offsets[n_tiles] = acc;
    resize(&mut out.ids, acc);
    let ids_w = Shared::new(&mut out.ids);
    recs.par_chunks(len)
        .zip(counts.par_chunks_mut(grid))
        .for_each(|(chunk, cur)| {
            for rec in chunk {
                let g = rec[0] as u32;
                let [x0, x1, y0, y1] = packing.unpack(rec[1]);
                for ty in y0..y1 {
                    for c in &mut cur[ty * gx + x0..ty * gx + x1] {
                        // SAFETY: chunk `c`'s cursor for tile `t` runs over
                        // `cursor[c][t]..cursor[c][t] + count[c][t]`, ranges disjoint
                        // across (chunk, tile) pairs by the prefix sum, all `< acc`, the
                        // length of `ids`; the counts were taken over the same records.
                        unsafe { ids_w.write(*c, g) };
                        *c += 1;
                    }
                }
            }
        });
}

/// Whether a splat is drawn (radii not both 0).
#[inline(always)]
fn visible(r: &[i32; 2]) -> bool {
    r[0] > 0 || r[1] > 0
}

/// The record of splat `gid`: `[depth_bits << 32 | gid, packed tile rectangle]`.
#[inline(always)]
fn record(s: &Splat, r: [i32; 2], gid: usize, (packing, tiles_x, tiles_y): Grid) -> [u64; 2] {
    let [x0, x1, y0, y1] = tile_rect(s.mean, r, tiles_x, tiles_y);
    // Negative radii could invert the rectangle: it is then empty.
    let rect = packing.pack([x0, x1.max(x0), y0, y1.max(y0)]);
    [u64::from(s.depth.to_bits()) << 32 | gid as u64, rect]
}

/// The tile grid: its packing and size.
type Grid = (Packing, usize, usize);

/// [`record`] of every visible splat of a chunk starting at Gaussian `first`, in index
/// order at the head of `out` (as long as the chunk; the entries past the returned count
/// are unspecified); returns the smallest and largest depth bits of the visible splats and
/// their count.
fn records(
    splats: &[Splat],
    radii: &[[i32; 2]],
    first: usize,
    grid: Grid,
    out: &mut [[u64; 2]],
) -> (u32, u32, usize) {
    let n = splats.len().min(radii.len()).min(out.len());
    let (mut lo, mut hi, mut count) = (u32::MAX, 0u32, 0usize);
    for (i, (s, &r)) in splats[..n].iter().zip(&radii[..n]).enumerate() {
        // Branch-free: every record is written at the cursor (`count ≤ i < n`), which
        // moves on past the visible ones only.
        out[count] = record(s, r, first + i, grid);
        let (vis, d) = (visible(&r), s.depth.to_bits());
        lo = if vis { lo.min(d) } else { lo };
        hi = if vis { hi.max(d) } else { hi };
        count += usize::from(vis);
    }
    (lo, hi, count)
}

/// A vector form's result over splats `..full` of `n`, `(lo, hi, count)`, completed by
/// [`records`] over the tail from the cursor (`count ≤ full`: its writes stay below `n`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn with_tail(
    splats: &[Splat],
    radii: &[[i32; 2]],
    first: usize,
    grid: Grid,
    out: &mut [[u64; 2]],
    (full, n): (usize, usize),
    (lo, hi, count): (u32, u32, usize),
) -> (u32, u32, usize) {
    let (tlo, thi, tcount) = records(
        &splats[full..n],
        &radii[full..n],
        first + full,
        grid,
        &mut out[count..n],
    );
    (lo.min(tlo), hi.max(thi), count + tcount)
}

/// [`records`], sixteen splats per AVX-512F instruction (the tail one at a time): the same
/// records. The splats' centres and depths are loaded by a 16×16 transpose, the radii by a
/// permute; the clamps below 0 and above 2^30 (exact in f32, above every grid [`Packing`]
/// accepts) happen in f32 before the conversions, the clamp to the grid after them in
/// integers (`clamp(floor(v), 0, hi)` is `min(trunc(clamp(v, 0, 2^30)), hi)` for an integer
/// `hi ≤ 2^30`, NaN → 0 by `max`'s operand order, as `tile_rect`'s saturating casts give;
/// a grid edge itself may not be an f32 above 2^24), the packing in 64-bit lanes.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::needless_range_loop)] // no iterators over vectors (see `math::lanes`)
unsafe fn records_avx512(
    splats: &[Splat],
    radii: &[[i32; 2]],
    first: usize,
    grid: Grid,
    out: &mut [[u64; 2]],
) -> (u32, u32, usize) {
    use crate::math::lanes::{F32x16, Lanes};
    use std::arch::x86_64::*;
    let (packing, tiles_x, tiles_y) = grid;
    let n = splats.len().min(radii.len()).min(out.len());
    let full = n - n % 16;
    let floats = Splat::floats(&splats[..n]);
    let (mut lo, mut hi, mut count) = (u32::MAX, 0u32, 0usize);
    // SAFETY (every intrinsic below): AVX-512F is available (the caller's contract); the
    // loads and stores are of slices of exactly the length they touch.
    unsafe {
        let zero = _mm512_setzero_ps();
        let tile = _mm512_set1_ps(TILE_SIZE as f32);
        let limit = _mm512_set1_ps((1u32 << 30) as f32);
        let (hx, hy) = (
            _mm512_set1_epi32(tiles_x as i32),
            _mm512_set1_epi32(tiles_y as i32),
        );
        let even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
        let odd = _mm512_add_epi32(even, _mm512_set1_epi32(1));
        let shift = |k: u32| _mm_cvtsi32_si128(k as i32);
        let (s_x1, s_y0, s_y1) = (
            shift(packing.bx),
            shift(2 * packing.bx),
            shift(2 * packing.bx + packing.by),
        );
        let first_pair = _mm512_setr_epi64(0, 1, 8, 9, 2, 3, 10, 11);
        let second_pair = _mm512_setr_epi64(4, 5, 12, 13, 6, 7, 14, 15);
        let mut vlo = _mm512_set1_epi32(-1);
        let mut vhi = _mm512_setzero_si512();
        let mut cols = [F32x16::splat(0.0); SPLAT_FLOATS];
        for k in (0..full).step_by(16) {
            F32x16::load_columns(&floats[k * SPLAT_FLOATS..], SPLAT_FLOATS, &mut cols);
            let (mx, my, depth) = (cols[0].0, cols[1].0, _mm512_castps_si512(cols[9].0));
            let rp = radii[k..k + 16].as_flattened().as_ptr();
            let (r0, r1) = (
                _mm512_loadu_si512(rp.cast()),
                _mm512_loadu_si512(rp.add(16).cast()),
            );
            let (rx, ry) = (
                _mm512_permutex2var_epi32(r0, even, r1),
                _mm512_permutex2var_epi32(r0, odd, r1),
            );
            let vis = _mm512_cmpgt_epi32_mask(rx, _mm512_setzero_si512())
                | _mm512_cmpgt_epi32_mask(ry, _mm512_setzero_si512());
            let (rxf, ryf) = (_mm512_cvtepi32_ps(rx), _mm512_cvtepi32_ps(ry));
            // clamp(v, 0, 2^30): `max(v, 0)` gives 0 for a NaN v (its second operand).
            let clamp = |v: __m512| _mm512_min_ps(_mm512_max_ps(v, zero), limit);
            let down = |v: __m512, hi: __m512i| _mm512_min_epi32(_mm512_cvttps_epi32(clamp(v)), hi);
            let up = |v: __m512, hi: __m512i| {
                let c =
                    _mm512_roundscale_ps::<{ _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC }>(clamp(v));
                _mm512_min_epi32(_mm512_cvttps_epi32(c), hi)
            };
            let x0 = down(_mm512_div_ps(_mm512_sub_ps(mx, rxf), tile), hx);
            let x1 = _mm512_max_epi32(up(_mm512_div_ps(_mm512_add_ps(mx, rxf), tile), hx), x0);
            let y0 = down(_mm512_div_ps(_mm512_sub_ps(my, ryf), tile), hy);
            let y1 = _mm512_max_epi32(up(_mm512_div_ps(_mm512_add_ps(my, ryf), tile), hy), y0);
            vlo = _mm512_mask_min_epu32(vlo, vis, vlo, depth);
            vhi = _mm512_mask_max_epu32(vhi, vis, vhi, depth);
            for half in 0..2 {
                let wide = |v: __m512i| {
                    _mm512_cvtepu32_epi64(if half == 0 {
                        _mm512_castsi512_si256(v)
                    } else {
                        _mm512_extracti64x4_epi64::<1>(v)
                    })
                };
                let rect = _mm512_or_si512(
                    _mm512_or_si512(wide(x0), _mm512_sll_epi64(wide(x1), s_x1)),
                    _mm512_or_si512(
                        _mm512_sll_epi64(wide(y0), s_y0),
                        _mm512_sll_epi64(wide(y1), s_y1),
                    ),
                );
                let gid = _mm512_add_epi64(
                    _mm512_set1_epi64((first + k + 8 * half) as i64),
                    _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7),
                );
                let key = _mm512_or_si512(_mm512_slli_epi64::<32>(wide(depth)), gid);
                let (a, b) = (
                    _mm512_unpacklo_epi64(key, rect),
                    _mm512_unpackhi_epi64(key, rect),
                );
                // Four records per register; the visible ones compressed to the cursor
                // (`count ≤ k + 8·half + 4·quarter`: the full store stays within the
                // chunk's records written or about to be).
                let quarters = [first_pair, second_pair];
                for (q, order) in quarters.into_iter().enumerate() {
                    let bits = (vis >> (8 * half + 4 * q)) & 0xf;
                    let keep = DOUBLED[bits as usize];
                    let recs =
                        _mm512_maskz_compress_epi64(keep, _mm512_permutex2var_epi64(a, order, b));
                    let dst = out[count..count + 4].as_flattened_mut().as_mut_ptr();
                    _mm512_storeu_si512(dst.cast(), recs);
                    count += bits.count_ones() as usize;
                }
            }
        }
        let (mut l16, mut h16) = ([0u32; 16], [0u32; 16]);
        _mm512_storeu_si512(l16.as_mut_ptr().cast(), vlo);
        _mm512_storeu_si512(h16.as_mut_ptr().cast(), vhi);
        for l in 0..16 {
            lo = lo.min(l16[l]);
            hi = hi.max(h16[l]);
        }
    }
    with_tail(splats, radii, first, grid, out, (full, n), (lo, hi, count))
}

/// [`records`] with the tile rectangles of eight splats per AVX2 instruction (the same
/// clamps and conversions as [`records_avx512`]), the records then packed and written at
/// the cursor lane by lane (AVX2 has no compress); the tail one at a time. The same records.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::needless_range_loop)] // lanes index five arrays together
unsafe fn records_avx2(
    splats: &[Splat],
    radii: &[[i32; 2]],
    first: usize,
    grid: Grid,
    out: &mut [[u64; 2]],
) -> (u32, u32, usize) {
    use crate::math::lanes::{F32x8, Lanes};
    use std::arch::x86_64::*;
    let (packing, tiles_x, tiles_y) = grid;
    let n = splats.len().min(radii.len()).min(out.len());
    let full = n - n % 8;
    let floats = Splat::floats(&splats[..n]);
    let (mut lo, mut hi, mut count) = (u32::MAX, 0u32, 0usize);
    // SAFETY (every intrinsic below): AVX2 is available (the caller's contract); the loads
    // and stores are of slices of exactly the length they touch.
    unsafe {
        let zero = _mm256_setzero_ps();
        let tile = _mm256_set1_ps(TILE_SIZE as f32);
        let limit = _mm256_set1_ps((1u32 << 30) as f32);
        let (hx, hy) = (
            _mm256_set1_epi32(tiles_x as i32),
            _mm256_set1_epi32(tiles_y as i32),
        );
        // A radii pair's x to the low half of its 128-bit lane, y to the high half.
        let split = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
        let mut cols = [F32x8::splat(0.0); SPLAT_FLOATS];
        let mut rect = [[0i32; 8]; 4];
        let mut depth = [0u32; 8];
        for k in (0..full).step_by(8) {
            F32x8::load_columns(&floats[k * SPLAT_FLOATS..], SPLAT_FLOATS, &mut cols);
            let (mx, my) = (cols[0].0, cols[1].0);
            let rp = radii[k..k + 8].as_flattened().as_ptr();
            let (r0, r1) = (
                _mm256_permutevar8x32_epi32(_mm256_loadu_si256(rp.cast()), split),
                _mm256_permutevar8x32_epi32(_mm256_loadu_si256(rp.add(8).cast()), split),
            );
            let (rx, ry) = (
                _mm256_permute2x128_si256::<0x20>(r0, r1),
                _mm256_permute2x128_si256::<0x31>(r0, r1),
            );
            let (rxf, ryf) = (_mm256_cvtepi32_ps(rx), _mm256_cvtepi32_ps(ry));
            // clamp(v, 0, 2^30): `max(v, 0)` gives 0 for a NaN v (its second operand).
            let clamp = |v: __m256| _mm256_min_ps(_mm256_max_ps(v, zero), limit);
            let down = |v: __m256, hi: __m256i| _mm256_min_epi32(_mm256_cvttps_epi32(clamp(v)), hi);
            let up = |v: __m256, hi: __m256i| {
                let c = _mm256_round_ps::<{ _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC }>(clamp(v));
                _mm256_min_epi32(_mm256_cvttps_epi32(c), hi)
            };
            let x0 = down(_mm256_div_ps(_mm256_sub_ps(mx, rxf), tile), hx);
            let x1 = _mm256_max_epi32(up(_mm256_div_ps(_mm256_add_ps(mx, rxf), tile), hx), x0);
            let y0 = down(_mm256_div_ps(_mm256_sub_ps(my, ryf), tile), hy);
            let y1 = _mm256_max_epi32(up(_mm256_div_ps(_mm256_add_ps(my, ryf), tile), hy), y0);
            for (dst, v) in rect.iter_mut().zip([x0, x1, y0, y1]) {
                _mm256_storeu_si256(dst.as_mut_ptr().cast(), v);
            }
            _mm256_storeu_si256(depth.as_mut_ptr().cast(), _mm256_castps_si256(cols[9].0));
            for l in 0..8 {
                let i = k + l;
                let r = [rect[0][l], rect[1][l], rect[2][l], rect[3][l]].map(|v| v as usize);
                // Branch-free, as `records`: written at the cursor, which moves on past the
                // visible ones only.
                out[count] = [
                    u64::from(depth[l]) << 32 | (first + i) as u64,
                    packing.pack(r),
                ];
                let vis = visible(&radii[i]);
                lo = if vis { lo.min(depth[l]) } else { lo };
                hi = if vis { hi.max(depth[l]) } else { hi };
                count += usize::from(vis);
            }
        }
    }
    with_tail(splats, radii, first, grid, out, (full, n), (lo, hi, count))
}

/// Bits `i` of a 4-bit mask doubled into bits `2i, 2i + 1` (a record is two 64-bit lanes).
#[cfg(target_arch = "x86_64")]
const DOUBLED: [u8; 16] = {
    let mut t = [0u8; 16];
    let mut m = 0;
    while m < 16 {
        let mut i = 0;
        while i < 4 {
            if m >> i & 1 == 1 {
                t[m] |= 0b11 << (2 * i);
            }
            i += 1;
        }
        m += 1;
    }
    t
};

/// Stable LSD radix sort of `recs[..n]` on the key `(rec[0] >> 32) − min`, of which only
/// the low `bits` bits may be set: `⌈bits/11⌉` passes of equal width, each from one buffer
/// into the other (swapped after it), so the sorted records end in `recs[..n]`. `tmp` is as
/// long as `recs`.
fn radix_sort(
    recs: &mut Vec<[u64; 2]>,
    tmp: &mut Vec<[u64; 2]>,
    (counts, running): (&mut Vec<usize>, &mut Vec<usize>),
    min: u32,
    bits: u32,
    n: usize,
) {
    let passes = bits.div_ceil(MAX_DIGIT_BITS);
    if passes == 0 {
        return;
    }
    let width = bits.div_ceil(passes);
    let buckets = 1usize << width;
    let mask = (1u32 << width) - 1;
    let len = chunk_len(n);
    let n_chunks = n.div_ceil(len);
    for pass in 0..passes {
        let shift = pass * width;
        let digit = move |r: &[u64; 2]| {
            ((((r[0] >> 32) as u32).wrapping_sub(min) >> shift) & mask) as usize
        };
        reset(counts, n_chunks * buckets);
        recs[..n]
            .par_chunks(len)
            .zip(counts.par_chunks_mut(buckets))
            .for_each(|(chunk, h)| {
                for r in chunk {
                    h[digit(r)] += 1;
                }
            });
        // Exclusive prefix sum in (digit, chunk) order; a pass where one digit holds every
        // record would leave the order unchanged and is skipped.
        cursors(counts, buckets, running, 0..buckets, |_, _| ());
        // A digit's records run from chunk 0's cursor to its end.
        let trivial = running
            .iter()
            .zip(&counts[..buckets])
            .any(|(end, start)| end - start == n);
        if !trivial {
            let dst = Shared::new(&mut tmp[..n]);
            recs[..n]
                .par_chunks(len)
                .zip(counts.par_chunks_mut(buckets))
                .for_each(|(chunk, cur)| {
                    for r in chunk {
                        let d = digit(r);
                        // SAFETY: chunk `c` writes digit `d` at `cursor[c][d]..cursor[c][d] +
                        // hist[c][d]`, ranges disjoint across (chunk, digit) pairs by the prefix
                        // sum, all `< n`, the length of `dst`.
                        unsafe { dst.write(cur[d], *r) };
                        cur[d] += 1;
                    }
                });
            std::mem::swap(recs, tmp);
        }
    }
}

/// Per-chunk counts `counts` (chunks of `cells` counters, in chunk order) turned in place
/// into write cursors: the exclusive prefix sum in (cell, chunk) order over the cells
/// `order` yields (each told its start by `start(i, at)`, `i` its rank), of which the sum
/// is returned; `running` ends holding each cell's end. Walked chunk by chunk, in memory
/// order (a walk in (cell, chunk) order strides by a chunk's length; measured, the change
/// was within noise: this is one helper for the digits and the tiles). Wrapping sums:
/// cells outside `order` may hold any value.
fn cursors(
    counts: &mut [usize],
    cells: usize,
    running: &mut Vec<usize>,
    order: impl Iterator<Item = usize>,
    mut start: impl FnMut(usize, usize),
) -> usize {
    running.clear();
    running.resize(cells, 0);
    for chunk in counts.chunks_exact(cells) {
        for (r, &v) in running.iter_mut().zip(chunk) {
            *r = r.wrapping_add(v);
        }
    }
    let mut acc = 0usize;
    for (i, cell) in order.enumerate() {
        start(i, acc);
        let total = running[cell];
        running[cell] = acc;
        acc = acc.wrapping_add(total);
    }
    for chunk in counts.chunks_exact_mut(cells) {
        for (r, v) in running.iter_mut().zip(chunk) {
            (*v, *r) = (*r, r.wrapping_add(*v));
        }
    }
    acc
}

/// `v` of length `len`, all zeros.
fn reset(v: &mut Vec<usize>, len: usize) {
    v.clear();
    v.resize(len, 0);
}

/// `v` of length `len` with unspecified contents: only a new tail is written, and a
/// buffer that must grow is replaced by a zeroed allocation (untouched pages, no memset).
fn resize<T: Copy + Default>(v: &mut Vec<T>, len: usize) {
    if v.capacity() < len {
        *v = vec![T::default(); len];
    } else {
        v.truncate(len);
        v.resize(len, T::default());
    }
}

/// A slice's base pointer shared by the threads of a parallel scatter, each writing
/// indices no other thread touches (the callers' SAFETY comments say why).
#[derive(Clone, Copy)]
pub(crate) struct Shared<T> {
    ptr: *mut T,
    len: usize,
}

// SAFETY: `Shared` only writes `Copy` values to indices the callers prove disjoint across
// threads, and the slice outlives the parallel section that uses it.
unsafe impl<T: Send> Send for Shared<T> {}
unsafe impl<T: Send> Sync for Shared<T> {}

impl<T: Copy> Shared<T> {
    pub(crate) fn new(v: &mut [T]) -> Self {
        Shared {
            ptr: v.as_mut_ptr(),
            len: v.len(),
        }
    }
    /// # Safety
    /// `i < len`, and no other thread reads or writes index `i` while the slice is shared.
    #[inline(always)]
    pub(crate) unsafe fn write(self, i: usize, v: T) {
        assert!(i < self.len);
        // SAFETY: in bounds and unaliased (the caller's contract).
        unsafe { self.ptr.add(i).write(v) }
    }
    /// `src` copied to indices `at..at + src.len()`.
    ///
    /// # Safety
    /// No other thread reads or writes those indices while the slice is shared (bounds are
    /// checked).
    pub(crate) unsafe fn write_slice(self, at: usize, src: &[T]) {
        assert!(at <= self.len && src.len() <= self.len - at);
        // SAFETY: in bounds (checked) and unaliased (the caller's contract); `src` is a
        // shared borrow, so it does not overlap the exclusively borrowed destination.
        unsafe { std::ptr::copy_nonoverlapping(src.as_ptr(), self.ptr.add(at), src.len()) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Uniform;

    /// The AVX2 and AVX-512F record passes against the scalar one, bit for bit: centres off the grid,
    /// on tile boundaries, NaN, ±∞ and beyond i32; radii culled, one-sided, negative,
    /// huge and `i32::MIN`/`MAX`; arbitrary depth bits; lengths with and without a tail;
    /// grids from 1×1 to 1000×3 tiles.
    #[test]
    fn record_pass_forms_agree() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let avx512 = std::arch::is_x86_feature_detected!("avx512f");
            let mut u = Uniform::new(11);
            let specials = [
                f32::NAN,
                f32::INFINITY,
                f32::NEG_INFINITY,
                3e9,
                -3e9,
                -0.0,
                16.0,
            ];
            // Grid edges above 2^24 are not f32 values (review finding: a clamp to
            // `tiles_x as f32` lost a column or overshot the grid there).
            let huge = (1 << 24) + 1;
            for (tiles_x, tiles_y) in [
                (1, 1),
                (16, 16),
                (64, 48),
                (1000, 3),
                (huge, 1),
                (3, huge + 2),
            ] {
                let grid = (Packing::new(tiles_x, tiles_y), tiles_x, tiles_y);
                let (w, h) = ((tiles_x * 16) as f32, (tiles_y * 16) as f32);
                for n in [0usize, 1, 15, 16, 17, 100, 333] {
                    let splats: Vec<Splat> = (0..n)
                        .map(|_| {
                            let mut coord = |extent: f32| match u.below(8) {
                                0 => specials[u.below(specials.len() as u32) as usize],
                                1 => (16 * u.below(70)) as f32,
                                // At and past the grid's far edge.
                                2 => extent + u.range(-64.0, 64.0),
                                _ => u.range(-40.0, extent + 40.0),
                            };
                            let mean = [coord(w), coord(h)];
                            Splat {
                                mean,
                                depth: f32::from_bits(u.below(1 << 16) << 16 | u.below(1 << 16)),
                                ..Splat::default()
                            }
                        })
                        .collect();
                    let radii: Vec<[i32; 2]> = (0..n)
                        .map(|_| {
                            let mut r = || match u.below(10) {
                                0 => 0,
                                1 => -(u.below(50) as i32),
                                2 => [i32::MAX, i32::MIN, 1 << 20, 1 << 25][u.below(4) as usize],
                                _ => u.below(300) as i32,
                            };
                            [r(), r()]
                        })
                        .collect();
                    let mut want = vec![[0u64; 2]; n];
                    let mut got = vec![[1u64; 2]; n];
                    let mut got2 = vec![[2u64; 2]; n];
                    let a = records(&splats, &radii, 5, grid, &mut want);
                    // SAFETY: AVX2 is available (checked above).
                    let c = unsafe { records_avx2(&splats, &radii, 5, grid, &mut got2) };
                    assert_eq!(a, c, "avx2: {n} splats, {tiles_x}×{tiles_y} tiles");
                    if avx512 {
                        // SAFETY: AVX-512F is available (checked above).
                        let b = unsafe { records_avx512(&splats, &radii, 5, grid, &mut got) };
                        assert_eq!(a, b, "{n} splats, {tiles_x}×{tiles_y} tiles");
                        assert_eq!(got[..b.2], want[..a.2], "{n} splats, {tiles_x}×{tiles_y}");
                    }
                    // The visible splats' records, in index order, at the head.
                    let visible: Vec<[u64; 2]> = (0..n)
                        .filter(|&i| visible(&radii[i]))
                        .map(|i| record(&splats[i], radii[i], 5 + i, grid))
                        .collect();
                    assert_eq!(a.2, visible.len());
                    assert_eq!(
                        want[..a.2],
                        visible[..],
                        "{n} splats, {tiles_x}×{tiles_y} tiles"
                    );
                    assert_eq!(
                        got2[..c.2],
                        visible[..],
                        "avx2: {n} splats, {tiles_x}×{tiles_y} tiles"
                    );
                }
            }
        }
    }
}
