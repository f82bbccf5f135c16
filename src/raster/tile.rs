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
//! disjoint ([`Shared`], bounds-checked; the one `unsafe` here).

use super::project::Projected;
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

/// Bin the visible splats (radii not both 0) of an image `width × height`.
///
/// Allocates its result and work area; [`bin_into`] reuses both across frames.
pub fn bin(p: &Projected, width: usize, height: usize) -> TileBins {
    let mut out = TileBins::default();
    bin_into(p, width, height, &mut BinScratch::default(), &mut out);
    out
}

/// Smallest chunk of every parallel pass. Chunk boundaries depend only on the input size,
/// never on the thread count (the result does not depend on them either: every pass is an
/// exact counting pass).
const CHUNK: usize = 8192;
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
    /// Per-chunk counters (visible splats, radix histograms, per-tile counts), turned into
    /// write cursors in place.
    counts: Vec<usize>,
}

/// A tile rectangle packed into a u64: `x0 | x1 << bx | y0 << 2bx | y1 << (2bx + by)`.
#[derive(Clone, Copy)]
struct Packing {
    bx: u32,
    by: u32,
}

impl Packing {
    fn new(tiles_x: usize, tiles_y: usize) -> Self {
        let bx = usize::BITS - tiles_x.leading_zeros();
        let by = usize::BITS - tiles_y.leading_zeros();
        // Fails only for grids of more than 2^30 tiles (2^38 pixels).
        assert!(
            2 * (bx + by) <= 64,
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
/// 1. Per fixed chunk of Gaussians (parallel): count the visible ones; an exclusive prefix
///    sum gives each chunk its first slot; then write, in index order, one record per
///    visible splat (`depth_bits << 32 | index`, its packed tile rectangle), and reduce
///    the minimum and maximum depth bits.
/// 2. Stable LSD radix sort of the records on `depth_bits − min` (only the bits the range
///    needs: `⌈bits/11⌉` passes of equal width ≤ 11 bits). Each pass: per-chunk
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
        counts,
    } = scratch;
    assert!(
        p.radii.len() <= u32::MAX as usize,
        "more Gaussians than u32 indices"
    );
    let packing = Packing::new(tiles_x, tiles_y);

    // 1. One record per visible splat, in index order.
    let visible = |r: &[i32; 2]| r[0] > 0 || r[1] > 0;
    let n_chunks = p.radii.len().div_ceil(CHUNK);
    reset(counts, n_chunks);
    p.radii
        .par_chunks(CHUNK)
        .zip(counts.par_iter_mut())
        .for_each(|(r, c)| *c = r.iter().filter(|r| visible(r)).count());
    let n = exclusive_prefix_sum(counts);
    resize(recs, n);
    let recs_w = Shared::new(recs);
    let (min, max) = (0..n_chunks)
        .into_par_iter()
        .map(|c| {
            let (mut lo, mut hi) = (u32::MAX, 0u32);
            let mut slot = counts[c];
            let first = c * CHUNK;
            let last = (first + CHUNK).min(p.radii.len());
            for (i, (&r, s)) in p.radii[first..last]
                .iter()
                .zip(&p.splats[first..last])
                .enumerate()
            {
                if !visible(&r) {
                    continue;
                }
                let d = s.depth.to_bits();
                let [x0, x1, y0, y1] = tile_rect(s.mean, r, tiles_x, tiles_y);
                // Negative radii could invert the rectangle: it is then empty.
                let rect = packing.pack([x0, x1.max(x0), y0, y1.max(y0)]);
                // SAFETY: chunk `c` writes the slots `counts[c]..counts[c + 1]` (its visible
                // count, from the prefix sum above), disjoint from every other chunk's and
                // `< n`, the length of `recs`.
                unsafe { recs_w.write(slot, [(d as u64) << 32 | (first + i) as u64, rect]) };
                slot += 1;
                lo = lo.min(d);
                hi = hi.max(d);
            }
            (lo, hi)
        })
        .reduce(|| (u32::MAX, 0), |a, b| (a.0.min(b.0), a.1.max(b.1)));

    // 2. Sort by (depth bits, Gaussian index).
    if n > 1 {
        radix_sort(
            recs,
            recs_tmp,
            counts,
            min,
            32 - (max - min).leading_zeros(),
        );
    }

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
    // Exclusive prefix sum in (tile, chunk) order: tile offsets and chunk cursors.
    let mut acc = 0usize;
    for ty in 0..tiles_y {
        for tx in 0..tiles_x {
            out.offsets[ty * tiles_x + tx] = acc;
            for c in 0..n_chunks {
                let k = c * grid + ty * gx + tx;
                let v = counts[k];
                counts[k] = acc;
                acc += v;
            }
        }
    }
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

/// Stable LSD radix sort of `recs` on the key `(rec[0] >> 32) − min`, of which only the
/// low `bits` bits may be set. `tmp` and `counts` are work buffers.
fn radix_sort(
    recs: &mut Vec<[u64; 2]>,
    tmp: &mut Vec<[u64; 2]>,
    counts: &mut Vec<usize>,
    min: u32,
    bits: u32,
) {
    let n = recs.len();
    if bits == 0 {
        return;
    }
    let passes = bits.div_ceil(MAX_DIGIT_BITS);
    let width = bits.div_ceil(passes);
    let buckets = 1usize << width;
    let mask = buckets as u32 - 1;
    let len = chunk_len(n);
    let n_chunks = n.div_ceil(len);
    resize(tmp, n);
    for pass in 0..passes {
        let shift = pass * width;
        let digit = move |r: &[u64; 2]| {
            ((((r[0] >> 32) as u32).wrapping_sub(min) >> shift) & mask) as usize
        };
        reset(counts, n_chunks * buckets);
        recs.par_chunks(len)
            .zip(counts.par_chunks_mut(buckets))
            .for_each(|(chunk, h)| {
                for r in chunk {
                    h[digit(r)] += 1;
                }
            });
        // Exclusive prefix sum in (digit, chunk) order; a pass where one digit holds every
        // record would leave the order unchanged and is skipped.
        let mut acc = 0usize;
        let mut trivial = false;
        for d in 0..buckets {
            let start = acc;
            for c in 0..n_chunks {
                let k = c * buckets + d;
                let v = counts[k];
                counts[k] = acc;
                acc += v;
            }
            trivial |= acc - start == n;
        }
        if trivial {
            continue;
        }
        let dst = Shared::new(tmp);
        recs.par_chunks(len)
            .zip(counts.par_chunks_mut(buckets))
            .for_each(|(chunk, cur)| {
                for r in chunk {
                    let d = digit(r);
                    // SAFETY: chunk `c` writes digit `d` at `cursor[c][d]..cursor[c][d] +
                    // hist[c][d]`, ranges disjoint across (chunk, digit) pairs by the prefix
                    // sum, all `< n`, the length of `tmp`.
                    unsafe { dst.write(cur[d], *r) };
                    cur[d] += 1;
                }
            });
        std::mem::swap(recs, tmp);
    }
}

/// Exclusive prefix sum in place; returns the total.
fn exclusive_prefix_sum(v: &mut [usize]) -> usize {
    let mut acc = 0;
    for x in v {
        let c = *x;
        *x = acc;
        acc += c;
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
struct Shared<T> {
    ptr: *mut T,
    len: usize,
}

// SAFETY: `Shared` only writes `Copy` values to indices the callers prove disjoint across
// threads, and the slice outlives the parallel section that uses it.
unsafe impl<T: Send> Send for Shared<T> {}
unsafe impl<T: Send> Sync for Shared<T> {}

impl<T: Copy> Shared<T> {
    fn new(v: &mut [T]) -> Self {
        Shared {
            ptr: v.as_mut_ptr(),
            len: v.len(),
        }
    }
    /// # Safety
    /// `i < len`, and no other thread reads or writes index `i` while the slice is shared.
    #[inline(always)]
    unsafe fn write(self, i: usize, v: T) {
        assert!(i < self.len);
        // SAFETY: in bounds and unaliased (the caller's contract).
        unsafe { self.ptr.add(i).write(v) }
    }
}
