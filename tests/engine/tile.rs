//! Tile binning (`raster::tile::bin`, `bin_into`) against the obvious sort + scatter, on
//! seeded random projections, for 1, 2 and 3 rayon threads.
use crate::support::with_threads;
use unseen::raster::Kernel;
use unseen::raster::project::{Projected, Splat};
use unseen::raster::tile::{BinScratch, TILE_SIZE, TileBins, bin, bin_into, tile_rect};
use unseen::rng::Uniform;

/// The tile rectangle as first written: `f32::floor` / `ceil`, then `as i64` clamped.
fn reference_rect(mean: [f32; 2], radii: [i32; 2], tiles_x: usize, tiles_y: usize) -> [usize; 4] {
    let t = TILE_SIZE as f32;
    let clampi = |v: f32, hi: usize| (v as i64).clamp(0, hi as i64) as usize;
    let (rx, ry) = (radii[0] as f32, radii[1] as f32);
    [
        clampi(((mean[0] - rx) / t).floor(), tiles_x),
        clampi(((mean[0] + rx) / t).ceil(), tiles_x),
        clampi(((mean[1] - ry) / t).floor(), tiles_y),
        clampi(((mean[1] + ry) / t).ceil(), tiles_y),
    ]
}

/// Visible splats sorted by (depth bits, index), pushed into per-tile lists in that order.
fn reference_bin(p: &Projected, width: usize, height: usize) -> TileBins {
    let (tiles_x, tiles_y) = (width.div_ceil(TILE_SIZE), height.div_ceil(TILE_SIZE));
    let mut order: Vec<(u32, u32)> = (0..p.radii.len())
        .filter(|&i| p.radii[i][0] > 0 || p.radii[i][1] > 0)
        .map(|i| (p.splats[i].depth.to_bits(), i as u32))
        .collect();
    order.sort();
    let mut lists = vec![Vec::new(); tiles_x * tiles_y];
    for (_, i) in order {
        let s = &p.splats[i as usize];
        let [x0, x1, y0, y1] = reference_rect(s.mean, p.radii[i as usize], tiles_x, tiles_y);
        for ty in y0..y1 {
            for tx in x0..x1 {
                lists[ty * tiles_x + tx].push(i);
            }
        }
    }
    let mut offsets = vec![0];
    for l in &lists {
        offsets.push(offsets.last().unwrap() + l.len());
    }
    TileBins {
        tiles_x,
        tiles_y,
        offsets,
        ids: lists.concat(),
    }
}

/// How a random projection is drawn.
#[derive(Clone, Copy, Debug)]
enum Depths {
    /// A handful of values: many exact ties.
    Few,
    /// Uniform in a narrow range (few key bits).
    Narrow,
    /// Log-uniform over 1e-4..1e8 (every exponent bit in play).
    Wide,
    /// All equal (no key bits: the sort has nothing to do).
    Equal,
    /// Arbitrary bit patterns (negative, NaN, infinite): still ordered by the bits.
    AnyBits,
}

fn random_projection(n: usize, w: usize, h: usize, depths: Depths, seed: u64) -> Projected {
    let mut u = Uniform::new(seed);
    let few = [0.5f32, 1.0, 2.0, 2.0000002, 7.25];
    let mut p = Projected::default();
    for _ in 0..n {
        let depth = match depths {
            Depths::Few => few[u.below(few.len() as u32) as usize],
            Depths::Narrow => u.range(2.0, 2.01),
            Depths::Wide => 10f32.powf(u.range(-4.0, 8.0)),
            Depths::Equal => 3.0,
            Depths::AnyBits => f32::from_bits((u.below(1 << 16) << 16) | u.below(1 << 16)),
        };
        let mean = match u.below(20) {
            // Off the grid, far or near.
            0 => [u.range(-1e4, 1e4), u.range(-1e4, 1e4)],
            1 => [u.range(-40.0, 0.0), u.range(h as f32, h as f32 + 40.0)],
            // On tile boundaries exactly.
            2 => [
                (16 * u.below(w as u32 / 16 + 2)) as f32,
                (16 * u.below(h as u32 / 16 + 2)) as f32,
            ],
            // Not finite or huge.
            3 => [
                [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 3e9, -3e9][u.below(5) as usize],
                u.range(0.0, h as f32),
            ],
            _ => [
                u.range(-20.0, w as f32 + 20.0),
                u.range(-20.0, h as f32 + 20.0),
            ],
        };
        let radii = match u.below(16) {
            // Culled.
            0..=2 => [0, 0],
            // One axis zero.
            3 => [0, u.below(30) as i32 + 1],
            4 => [u.below(30) as i32 + 1, 0],
            // Covering every tile.
            5 => [1 << 20, 1 << 20],
            // Negative (not made by the projection): an empty rectangle, never a panic.
            6 => [-(u.below(40) as i32) - 1, u.below(40) as i32 + 1],
            7 => [u.below(200) as i32 + 1, u.below(200) as i32 + 1],
            _ => [u.below(24) as i32 + 1, u.below(24) as i32 + 1],
        };
        p.splats.push(Splat {
            mean,
            depth,
            ..Default::default()
        });
        p.radii.push(radii);
    }
    p
}

fn assert_same(got: &TileBins, want: &TileBins, what: &str) {
    assert_eq!(
        (got.tiles_x, got.tiles_y),
        (want.tiles_x, want.tiles_y),
        "{what}: grid"
    );
    assert_eq!(got.offsets, want.offsets, "{what}: offsets");
    assert_eq!(got.ids, want.ids, "{what}: ids");
}

#[test]
fn bin_matches_reference_sort_and_scatter() {
    // Sizes around the chunk boundaries (2048, and the record pass's 16-splat blocks;
    // 32 chunks from 65 536 on).
    let sizes = [
        0usize, 1, 2, 3, 17, 1000, 2047, 2048, 2049, 8191, 8193, 16_385, 270_001,
    ];
    let images = [
        (256, 256),
        (37, 21),
        (1, 1),
        (16, 16),
        (17, 33),
        (1024, 768),
        (100, 3),
    ];
    let depths = [
        Depths::Few,
        Depths::Narrow,
        Depths::Wide,
        Depths::Equal,
        Depths::AnyBits,
    ];
    let mut cases = Vec::new();
    let mut seed = 0;
    for (k, &n) in sizes.iter().enumerate() {
        for (j, &(w, h)) in images.iter().enumerate() {
            // Every size with every image for the small sizes; fewer for the large ones.
            if n > 20_000 && j % 3 != 0 || n > 200_000 && j != 5 {
                continue;
            }
            let d = depths[(k + j) % depths.len()];
            seed += 1;
            cases.push((random_projection(n, w, h, d, seed), w, h, d));
        }
    }
    // One visible splat among culled ones; every splat culled; a zero-width image.
    let mut one = random_projection(5000, 64, 64, Depths::Wide, 99);
    for (i, r) in one.radii.iter_mut().enumerate() {
        *r = if i == 4321 { [3, 3] } else { [0, 0] };
    }
    cases.push((one, 64, 64, Depths::Wide));
    let mut none = random_projection(9000, 64, 64, Depths::Few, 98);
    none.radii.iter_mut().for_each(|r| *r = [0, 0]);
    cases.push((none, 64, 64, Depths::Few));
    cases.push((
        random_projection(50, 0, 40, Depths::Few, 97),
        0,
        40,
        Depths::Few,
    ));

    for threads in [1, 2, 3] {
        with_threads(threads, || {
            // One scratch and output reused across every case (stale contents must not leak).
            let (mut scratch, mut out) = (BinScratch::default(), TileBins::default());
            for (i, (p, w, h, d)) in cases.iter().enumerate() {
                let want = reference_bin(p, *w, *h);
                let what = format!(
                    "case {i}: {} splats, {w}×{h}, {d:?}, {threads} threads",
                    p.radii.len()
                );
                // Both record-pass forms (AVX-512F where the CPU has it, and scalar).
                for kernel in [Kernel::Auto, Kernel::Scalar] {
                    assert_same(
                        &bin(p, *w, *h, kernel),
                        &want,
                        &format!("{what}, {kernel:?}"),
                    );
                    bin_into(p, *w, *h, kernel, &mut scratch, &mut out);
                    assert_same(&out, &want, &format!("{what}, {kernel:?}, bin_into"));
                }
            }
        });
    }
}

#[test]
fn tile_rect_matches_floor_ceil_clamp() {
    let mut u = Uniform::new(5);
    let special = [
        0.0f32,
        -0.0,
        1e-45,
        -1e-45,
        0.5,
        -0.5,
        15.999999,
        16.0,
        16.000002,
        -16.0,
        8_388_607.5,
        16_777_215.0,
        16_777_216.0,
        16_777_218.0,
        3e9,
        -3e9,
        1e30,
        f32::MAX,
        f32::MIN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
    ];
    let grids = [
        (1usize, 1usize),
        (16, 16),
        (64, 48),
        (1 << 20, 3),
        (3, 1 << 25),
    ];
    for &(tx, ty) in &grids {
        for _ in 0..20_000 {
            let pick = |u: &mut Uniform| match u.below(3) {
                0 => special[u.below(special.len() as u32) as usize],
                1 => u.range(-100.0, 2000.0),
                _ => 16.0 * u.below(200) as f32 - 1600.0,
            };
            let mean = [pick(&mut u), pick(&mut u)];
            let radii = [u.below(100) as i32, u.below(100) as i32];
            assert_eq!(
                tile_rect(mean, radii, tx, ty),
                reference_rect(mean, radii, tx, ty),
                "mean {mean:?} radii {radii:?} grid {tx}×{ty}"
            );
        }
        for &a in &special {
            for &b in &special {
                for r in [0, 1, 7, 1 << 20] {
                    assert_eq!(
                        tile_rect([a, b], [r, r], tx, ty),
                        reference_rect([a, b], [r, r], tx, ty),
                        "mean {a}, {b} radius {r}"
                    );
                }
            }
        }
    }
}
