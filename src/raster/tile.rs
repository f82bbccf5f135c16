//! Tile binning: which Gaussians touch which 16×16 tile, each tile's list sorted front to back.
//!
//! A Gaussian with centre `m` and radii `r` touches the tiles
//! `[floor((m−r)/16), ceil((m+r)/16))` in x and y, clamped to the grid (gsplat
//! `intersect_tile`). Lists are ordered by the total order (camera z, Gaussian index): the
//! visible Gaussians are sorted once by that key, then scattered into per-tile lists in that
//! order, so every list is sorted and the result does not depend on the thread count.

use super::project::Projected;
use crate::math::round::{ceil, floor};
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
    let clampi = |v: f32, hi: usize| -> usize {
        // `as` saturates, NaN → 0; the value is then clamped to [0, hi].
        let v = v as i64;
        v.clamp(0, hi as i64) as usize
    };
    let (rx, ry) = (radii[0] as f32, radii[1] as f32);
    [
        clampi(floor((mean[0] - rx) / t), tiles_x),
        clampi(ceil((mean[0] + rx) / t), tiles_x),
        clampi(floor((mean[1] - ry) / t), tiles_y),
        clampi(ceil((mean[1] + ry) / t), tiles_y),
    ]
}

/// Bin the visible splats (radii not both 0) of an image `width × height`.
pub fn bin(p: &Projected, width: usize, height: usize) -> TileBins {
    let tiles_x = width.div_ceil(TILE_SIZE);
    let tiles_y = height.div_ceil(TILE_SIZE);
    // Sort key: depth bits (z > 0, so the IEEE bits order like the values) then index. The
    // tile rectangle travels with the key, computed here in index order (sequential reads),
    // so nothing below touches the splats again.
    let mut order: Vec<(u64, [usize; 4])> = p
        .radii
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .filter(|(_, r)| r[0] > 0 || r[1] > 0)
        .map(|(i, &r)| {
            let key = ((p.splats[i].depth.to_bits() as u64) << 32) | i as u64;
            (key, tile_rect(p.splats[i].mean, r, tiles_x, tiles_y))
        })
        .collect();
    order.par_sort_unstable_by_key(|e| e.0);
    let mut counts = vec![0usize; tiles_x * tiles_y + 1];
    for (_, r) in &order {
        for ty in r[2]..r[3] {
            for c in &mut counts[ty * tiles_x + r[0]..ty * tiles_x + r[1]] {
                *c += 1;
            }
        }
    }
    // Exclusive prefix sum -> offsets.
    let mut offsets = Vec::with_capacity(counts.len());
    let mut acc = 0usize;
    for c in &counts {
        offsets.push(acc);
        acc += c;
    }
    let mut cursor = offsets.clone();
    let mut ids = vec![0u32; acc];
    for &(k, r) in &order {
        let i = (k & 0xffff_ffff) as u32;
        for ty in r[2]..r[3] {
            for tx in r[0]..r[1] {
                let t = ty * tiles_x + tx;
                ids[cursor[t]] = i;
                cursor[t] += 1;
            }
        }
    }
    offsets.truncate(tiles_x * tiles_y + 1);
    TileBins {
        tiles_x,
        tiles_y,
        offsets,
        ids,
    }
}
