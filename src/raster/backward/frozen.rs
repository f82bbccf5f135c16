//! Frozen geometry: when only the SH colours train (the QA-Mask fine-tune), every splat's
//! α at every pixel is fixed, so the blend can be recorded once per camera and replayed.
//! The record holds α per blended (pixel, splat) pair, grouped in (tile row, splat) visits
//! in the backward's walk order (SPEC.md §5.9). Forward: `C = Σ c·w` with the forward's own
//! `w = α·T, T ← T·(1 − α)`, front to back; backward: per visit, `fac·v_rgb` with the
//! backward's own `fac = α·T` (transmittance recovered back to front from the final `T`)
//! added into the (tile, splat) lane-pair accumulators in the backward's visit order,
//! reduced once per tile as the backward does. Both replays give the same bits as the full
//! passes (tests `frozen_replay_*`), at a fraction of the cost: no projection, no σ, no
//! exp.
//!
//! The SH backward's per-visit loop has an AVX2 form (`visit_avx2`, full-width visits,
//! when the record's kernel allows AVX2), the scalar loop's operations one for one. The
//! forward replay of a tile row and the backward's transmittance recovery run sixteen lanes
//! per instruction on AVX-512F (`replay_row_avx512`, `recover_visit_avx512`: a visit's α
//! expanded into its lanes) and eight on AVX2 (`replay_row_avx2`, `recover_visit_avx2`: the
//! α placed in a 16-lane row), with masks for the lanes that blend.
//!
//! A lane that did not blend has `fac = 0`: its term `0·v` is ±0 where the full pass adds
//! a masked +0.0, and since the accumulators are never −0.0 (SPEC.md §5.8) the sums agree.
//! The forward replay skips such a lane, as the forward does.

use super::composite::{HALF, SplatGrad, add_pairs, recover, sum8};
use super::project::{GradGroups, Gradients, project_backward};
use super::render_for_backward;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::math::sh::num_coeffs;
#[cfg(target_arch = "x86_64")]
use crate::raster::composite::splat_alpha16;
use crate::raster::composite::{splat_alpha, splat_rows};
use crate::raster::kernel::Kernel;
use crate::raster::plan::RenderPlan;
use crate::raster::project::{
    ALPHA_THRESHOLD, CameraF32, Projected, Splat, sh_colors, sh_view_basis,
};
use crate::raster::tile::{TILE_SIZE, TileBins};
use crate::raster::{Outputs, RenderOptions};
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

const LANES: usize = TILE_SIZE;

/// Recorded blend of one camera: for every tile row, the splats that blend there (back to
/// front, the backward's walk order) and their α at each pixel of the row. Both replays
/// rebuild their weights from α with the passes' own recurrences: the forward's
/// `w = α·T, T ← T·(1 − α)` front to back from `T = 1`, the backward's `recover` back to
/// front from the final `T`. α is the one per-pair value either pass needs, so a record
/// holds 4 bytes per blended pair plus 6 per (row, splat) visit (SPEC.md §5.8, "Frozen
/// geometry").
pub struct FrozenBlend {
    /// Unique per record ([`FrozenWork`] checks it).
    id: u64,
    /// The geometry the record was made with (no SH); every replay checks the scene still
    /// has it. Shared between the records of one scene ([`FrozenBlend::record_shared`]).
    geometry: Arc<Gaussians>,
    cam: CameraF32,
    /// The options and plan of the recorded render.
    opts: RenderOptions,
    plan: RenderPlan,
    /// Per Gaussian: has a splat in this view (radius > 0).
    visible: Vec<bool>,
    bins: TileBins,
    final_t: Vec<f32>,
    /// Tile row `r = t·TILE_SIZE + row` (rows past the image's bottom are empty): visits
    /// `row_visits[r]..row_visits[r+1]`, their α from `row_alpha[r]`.
    row_visits: Vec<usize>,
    row_alpha: Vec<usize>,
    /// Per visit, back to front within its row: the intersection index (into `bins.ids`)
    /// and the run of lanes `[first, first + count)` whose α follow in `alpha` (lanes of
    /// the run that do not blend hold α = 0; lanes outside it do not blend).
    visit_k: Vec<u32>,
    visit_lanes: Vec<[u8; 2]>,
    alpha: Vec<f32>,
    /// The recording's kernel choice: the replayed SH backward uses [`visit_avx2`] where
    /// `kernel.avx2()`, else the scalar loop (same bits).
    kernel: Kernel,
}

/// The geometric parameters of `scene` (means, scales, rotations, opacities; no SH).
pub fn geometry_of(scene: &Gaussians) -> Gaussians {
    Gaussians {
        means: scene.means.clone(),
        log_scales: scene.log_scales.clone(),
        quats: scene.quats.clone(),
        opacity_logits: scene.opacity_logits.clone(),
        sh_degree: scene.sh_degree,
        ..Default::default()
    }
}

/// Bitwise equality of the geometric parameters.
fn same_geometry(scene: &Gaussians, g: &Gaussians) -> bool {
    // Blocks whose bit differences are OR-ed without an early exit (that vectorizes; a
    // per-element exit made this 3 % of a QA-Mask fine-tune).
    fn eq(a: &[f32], b: &[f32]) -> bool {
        a.len() == b.len()
            && a.chunks(256).zip(b.chunks(256)).all(|(x, y)| {
                x.iter()
                    .zip(y)
                    .fold(0u32, |d, (x, y)| d | (x.to_bits() ^ y.to_bits()))
                    == 0
            })
    }
    scene.sh_degree == g.sh_degree
        && eq(scene.means.as_flattened(), g.means.as_flattened())
        && eq(scene.log_scales.as_flattened(), g.log_scales.as_flattened())
        && eq(scene.quats.as_flattened(), g.quats.as_flattened())
        && eq(&scene.opacity_logits, &g.opacity_logits)
}

/// The record of one band (tile row of tiles): per tile row its visit and α counts, then
/// the visits and α in order.
#[derive(Default)]
struct BandRecord {
    row_visits: Vec<usize>,
    row_alpha: Vec<usize>,
    visit_k: Vec<u32>,
    visit_lanes: Vec<[u8; 2]>,
    alpha: Vec<f32>,
}

/// A tile row's lanes for [`blended_alpha`]: pixel centres x, the row's y, the splat's list
/// position, each lane's `n_contrib`, the lanes inside the image, the α clamp.
type RowLanes<'a> = (&'a [f32; LANES], f32, u32, &'a [u32; LANES], usize, f32);

/// The α of splat `s` in each lane of a tile row where the forward blended it (before the
/// lane's `n_contrib`, σ ≥ 0, α ≥ the threshold; lanes past `cols` never), else 0.
fn blended_alpha(s: &Splat, (px, py, pos, n, cols, max_alpha): RowLanes) -> [f32; LANES] {
    let mut a = [0f32; LANES];
    for l in 0..cols {
        let sa = splat_alpha(s, s.mean[0] - px[l], s.mean[1] - py, max_alpha);
        let valid = (pos < n[l]) & (sa.sigma >= 0.0) & (sa.alpha >= ALPHA_THRESHOLD);
        if valid {
            a[l] = sa.alpha;
        }
    }
    a
}

/// [`blended_alpha`] sixteen lanes per instruction (the forward kernel's arithmetic,
/// [`splat_alpha16`]): the same values.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn blended_alpha_avx512(
    s: &Splat,
    (px, py, pos, n, cols, max_alpha): RowLanes,
) -> [f32; LANES] {
    use std::arch::x86_64::*;
    let mut a = [0f32; LANES];
    // SAFETY: AVX-512F is available (the caller's contract); the loads and the store are
    // of 16-lane arrays.
    unsafe {
        let (neg_sigma, alpha) = splat_alpha16(
            s,
            _mm512_loadu_ps(px.as_ptr()),
            py,
            _mm512_set1_ps(max_alpha),
        );
        let nv = _mm512_loadu_si512(n.as_ptr().cast());
        let inside = if cols >= LANES {
            u16::MAX
        } else {
            (1u16 << cols) - 1
        };
        let valid = inside
            & _mm512_cmpgt_epu32_mask(nv, _mm512_set1_epi32(pos as i32))
            & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(neg_sigma, _mm512_setzero_ps())
            & _mm512_cmp_ps_mask::<_CMP_GE_OQ>(alpha, _mm512_set1_ps(ALPHA_THRESHOLD));
        _mm512_storeu_ps(a.as_mut_ptr(), _mm512_maskz_mov_ps(valid, alpha));
    }
    a
}

impl FrozenBlend {
    /// Render once and record the blend. The geometry (everything but SH) must not change
    /// while the record is used.
    pub fn record(scene: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Result<FrozenBlend> {
        Self::record_shared(scene, cam, opts, Arc::new(geometry_of(scene)))
    }

    /// [`FrozenBlend::record`] with a geometry snapshot ([`geometry_of`]) shared by every
    /// camera's record, so many records cost one copy of the geometry.
    pub fn record_shared(
        scene: &Gaussians,
        cam: &Camera,
        opts: &RenderOptions,
        geometry: Arc<Gaussians>,
    ) -> Result<FrozenBlend> {
        if !same_geometry(scene, &geometry) {
            return Err(Error::invalid(
                "the geometry snapshot does not match the scene being recorded",
            ));
        }
        let opts = RenderOptions {
            outputs: Outputs {
                rgb: true,
                ..Outputs::RGB
            },
            ..opts.clone()
        };
        let fwd = render_for_backward(scene, cam, &opts)?;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let (p, bins) = (&fwd.projected, &fwd.bins);
        let final_t = fwd.render.final_t.expect("backward state");
        let n_contrib = fwd.render.n_contrib.as_ref().expect("backward state");
        let cull = fwd.plan.cull_rows;
        let max_alpha = fwd.plan.conventions.max_alpha();
        if bins.ids.len() > u32::MAX as usize {
            return Err(Error::invalid(format!(
                "{} tile intersections: a frozen-blend record indexes them in 32 bits",
                bins.ids.len()
            )));
        }
        // Each tile row walks back to front exactly as the backward does; a lane blends
        // where the forward blended it (before `n_contrib`, σ ≥ 0, α ≥ the threshold).
        #[cfg(target_arch = "x86_64")]
        let avx512 = opts.kernel.avx512();
        let bands: Vec<BandRecord> = (0..bins.tiles_y)
            .into_par_iter()
            .map(|ty| {
                let y0 = ty * TILE_SIZE;
                let rows = TILE_SIZE.min(h - y0);
                let mut rec = BandRecord::default();
                for tx in 0..bins.tiles_x {
                    let t = ty * bins.tiles_x + tx;
                    let (x0, cols) = (tx * TILE_SIZE, TILE_SIZE.min(w - tx * TILE_SIZE));
                    let ids = bins.tile(t);
                    for row in 0..TILE_SIZE {
                        rec.row_visits.push(rec.visit_k.len());
                        rec.row_alpha.push(rec.alpha.len());
                        if row >= rows {
                            continue;
                        }
                        let mut n = [0u32; LANES];
                        for (l, n) in n.iter_mut().enumerate().take(cols) {
                            *n = n_contrib[(y0 + row) * w + x0 + l];
                        }
                        let max_n = n.iter().copied().max().unwrap_or(0) as usize;
                        let py = (y0 + row) as f32 + 0.5;
                        let px: [f32; LANES] = std::array::from_fn(|l| (x0 + l) as f32 + 0.5);
                        for pos in (0..max_n).rev() {
                            let gid = ids[pos] as usize;
                            let (lo, hi) = splat_rows(p, gid, y0, rows, cull);
                            if (row as u32) < lo || (row as u32) >= hi {
                                continue;
                            }
                            let s = &p.splats[gid];
                            let lane = (&px, py, pos as u32, &n, cols, max_alpha);
                            #[cfg(target_arch = "x86_64")]
                            let a = if avx512 {
                                // SAFETY: AVX-512F was detected (`Kernel::avx512`).
                                unsafe { blended_alpha_avx512(s, lane) }
                            } else {
                                blended_alpha(s, lane)
                            };
                            #[cfg(not(target_arch = "x86_64"))]
                            let a = blended_alpha(s, lane);
                            let Some(first) = a.iter().position(|&v| v > 0.0) else {
                                continue;
                            };
                            let last = a.iter().rposition(|&v| v > 0.0).expect("first exists");
                            rec.visit_k.push((bins.offsets[t] + pos) as u32);
                            rec.visit_lanes
                                .push([first as u8, (last + 1 - first) as u8]);
                            rec.alpha.extend_from_slice(&a[first..=last]);
                        }
                    }
                }
                rec
            })
            .collect();
        let mut out = BandRecord::default();
        for band in bands {
            let (v0, a0) = (out.visit_k.len(), out.alpha.len());
            out.row_visits
                .extend(band.row_visits.iter().map(|&v| v0 + v));
            out.row_alpha.extend(band.row_alpha.iter().map(|&a| a0 + a));
            out.visit_k.extend(band.visit_k);
            out.visit_lanes.extend(band.visit_lanes);
            out.alpha.extend(band.alpha);
        }
        out.row_visits.push(out.visit_k.len());
        out.row_alpha.push(out.alpha.len());
        let visible = p.radii.iter().map(|r| *r != [0, 0]).collect();
        Ok(FrozenBlend {
            id: NEXT_RECORD.fetch_add(1, Ordering::Relaxed),
            geometry,
            cam: CameraF32::new(cam),
            kernel: opts.kernel,
            opts,
            plan: fwd.plan,
            visible,
            bins: fwd.bins,
            final_t,
            row_visits: out.row_visits,
            row_alpha: out.row_alpha,
            visit_k: out.visit_k,
            visit_lanes: out.visit_lanes,
            alpha: out.alpha,
        })
    }

    /// Heap bytes held by this record (the shared geometry not counted).
    pub fn heap_bytes(&self) -> usize {
        fn b<T>(v: &[T]) -> usize {
            std::mem::size_of_val(v)
        }
        b(&self.visible)
            + b(&self.bins.ids)
            + b(&self.bins.offsets)
            + b(&self.final_t)
            + b(&self.row_visits)
            + b(&self.row_alpha)
            + b(&self.visit_k)
            + b(&self.visit_lanes)
            + b(&self.alpha)
    }

    /// Per Gaussian: has a splat in this view (a Gaussian without one gets no gradient
    /// from it).
    pub fn visible(&self) -> &[bool] {
        &self.visible
    }

    /// Blended (pixel, splat) pairs of the record.
    pub fn pairs(&self) -> usize {
        self.alpha.iter().filter(|&&a| a > 0.0).count()
    }

    /// The replay is valid only for the recorded geometry: compare it bit for bit (a few MB
    /// of memory comparison, far cheaper than the replay).
    fn check(&self, scene: &Gaussians) -> Result<()> {
        if same_geometry(scene, &self.geometry) {
            Ok(())
        } else {
            Err(Error::invalid(
                "the scene's geometry changed since the frozen blend was recorded; record it again",
            ))
        }
    }

    /// Per-Gaussian SH sums (before the clamp) and colours (after it) for the scene's
    /// current SH, into `ws`.
    fn colors(&self, scene: &Gaussians, ws: &mut FrozenWork) {
        let degree = self.plan.sh_degree;
        ws.raw.resize(scene.len(), [0.0; 3]);
        ws.colors.resize(scene.len(), [0.0; 3]);
        // Fixed chunks; the visible Gaussians of each in lanes (`sh_colors`: the
        // projection's colour code, the same bits in every lane width).
        const CHUNK: usize = 1024;
        ws.raw
            .par_chunks_mut(CHUNK)
            .zip(ws.colors.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (raw, col))| {
                let first = c * CHUNK;
                let visible = &self.visible[first..first + raw.len()];
                sh_colors(scene, first, visible, &self.cam, degree, self.kernel, raw);
                for (col, raw) in col.iter_mut().zip(raw.iter()) {
                    *col = raw.map(|v| if v > 0.0 { v } else { 0.0 });
                }
            });
        ws.record = self.id;
    }

    /// The forward replay of tile row `r` (its visits front to back, the record's order
    /// reversed): per lane `c += col·w` with the forward's `w = α·T`, `T ← T·(1 − α)`, from
    /// `T = 1`, skipping lanes that did not blend. Colour planes, one per channel.
    #[inline(always)]
    fn replay_row(&self, r: usize, colors: &[[f32; 3]]) -> [[f32; LANES]; 3] {
        let mut c = [[0f32; LANES]; 3];
        let mut tr = [1f32; LANES];
        let mut a_end = self.row_alpha[r + 1];
        for v in (self.row_visits[r]..self.row_visits[r + 1]).rev() {
            let col = colors[self.bins.ids[self.visit_k[v] as usize] as usize];
            let [first, count] = self.visit_lanes[v].map(usize::from);
            let alphas = &self.alpha[a_end - count..a_end];
            a_end -= count;
            for (j, &a) in alphas.iter().enumerate() {
                if a > 0.0 {
                    let l = first + j;
                    let wt = a * tr[l];
                    for ch in 0..3 {
                        c[ch][l] += col[ch] * wt;
                    }
                    tr[l] *= 1.0 - a;
                }
            }
        }
        c
    }

    /// [`FrozenBlend::replay_row`] sixteen lanes per instruction: a visit's α expanded
    /// into its lanes (`vexpandps`), the lanes that blend as a mask, the same multiplies
    /// and adds per lane (masked adds and multiplies keep the other lanes as they are).
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn replay_row_avx512(&self, r: usize, colors: &[[f32; 3]]) -> [[f32; LANES]; 3] {
        use std::arch::x86_64::*;
        let zero = _mm512_setzero_ps();
        let one = _mm512_set1_ps(1.0);
        let (mut c, mut tr) = ([zero; 3], one);
        let mut a_end = self.row_alpha[r + 1];
        for v in (self.row_visits[r]..self.row_visits[r + 1]).rev() {
            let col = colors[self.bins.ids[self.visit_k[v] as usize] as usize];
            let [first, count] = self.visit_lanes[v].map(usize::from);
            let alphas = &self.alpha[a_end - count..a_end];
            a_end -= count;
            let run = run_mask(first, alphas.len());
            // SAFETY: the expanding load reads popcount(run) = `alphas.len()` values from
            // the start of `alphas`.
            let a = unsafe { _mm512_maskz_expandloadu_ps(run, alphas.as_ptr()) };
            let blends = _mm512_mask_cmp_ps_mask::<_CMP_GT_OQ>(run, a, zero);
            let wt = _mm512_mul_ps(a, tr);
            for (ch, c) in c.iter_mut().enumerate() {
                let term = _mm512_mul_ps(_mm512_set1_ps(col[ch]), wt);
                *c = _mm512_mask_add_ps(*c, blends, *c, term);
            }
            tr = _mm512_mask_mul_ps(tr, blends, tr, _mm512_sub_ps(one, a));
        }
        let mut out = [[0f32; LANES]; 3];
        for (o, c) in out.iter_mut().zip(c) {
            // SAFETY: `o` holds 16 f32.
            unsafe { _mm512_storeu_ps(o.as_mut_ptr(), c) };
        }
        out
    }

    /// [`FrozenBlend::replay_row`] eight lanes per instruction: a visit's α placed in its
    /// lanes of a 16-lane row (0 elsewhere, lanes that do not blend either), the same
    /// multiplies and adds per lane under the mask of the lanes that blend.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn replay_row_avx2(&self, r: usize, colors: &[[f32; 3]]) -> [[f32; LANES]; 3] {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_ps();
        let one = _mm256_set1_ps(1.0);
        let (mut c, mut tr) = ([[zero; 2]; 3], [one; 2]);
        let mut a_end = self.row_alpha[r + 1];
        for v in (self.row_visits[r]..self.row_visits[r + 1]).rev() {
            let col = colors[self.bins.ids[self.visit_k[v] as usize] as usize];
            let [first, count] = self.visit_lanes[v].map(usize::from);
            let mut a = [0f32; LANES];
            a[first..first + count].copy_from_slice(&self.alpha[a_end - count..a_end]);
            a_end -= count;
            for h in 0..2 {
                // SAFETY: `a[8h..8h + 8]` holds 8 f32.
                let av = unsafe { _mm256_loadu_ps(a.as_ptr().add(8 * h)) };
                let blends = _mm256_cmp_ps::<_CMP_GT_OQ>(av, zero);
                let wt = _mm256_mul_ps(av, tr[h]);
                for (ch, c) in c.iter_mut().enumerate() {
                    let sum = _mm256_add_ps(c[h], _mm256_mul_ps(_mm256_set1_ps(col[ch]), wt));
                    c[h] = _mm256_blendv_ps(c[h], sum, blends);
                }
                let next = _mm256_mul_ps(tr[h], _mm256_sub_ps(one, av));
                tr[h] = _mm256_blendv_ps(tr[h], next, blends);
            }
        }
        let mut out = [[0f32; LANES]; 3];
        for (o, c) in out.iter_mut().zip(c) {
            for (h, c) in c.into_iter().enumerate() {
                // SAFETY: `o[8h..8h + 8]` holds 8 f32.
                unsafe { _mm256_storeu_ps(o.as_mut_ptr().add(8 * h), c) };
            }
        }
        out
    }

    /// The RGB render for the scene's current SH: the same bits as a full render.
    pub fn render_rgb(&self, scene: &Gaussians) -> Result<Vec<f32>> {
        let mut rgb = Vec::new();
        self.render_rgb_with(scene, &mut FrozenWork::default(), &mut rgb)?;
        Ok(rgb)
    }

    /// [`FrozenBlend::render_rgb`] into `rgb`, keeping in `ws` what the backward of this
    /// render needs (the SH sums, so the clamp is the render's, as autograd would have it).
    pub fn render_rgb_with(
        &self,
        scene: &Gaussians,
        ws: &mut FrozenWork,
        rgb: &mut Vec<f32>,
    ) -> Result<()> {
        self.check(scene)?;
        self.colors(scene, ws);
        let (w, h) = (self.cam.width as usize, self.cam.height as usize);
        let (bg, apply) = (self.opts.background, self.plan.apply_background);
        let (colors, bins) = (&ws.colors, &self.bins);
        #[cfg(target_arch = "x86_64")]
        let (avx2, avx512) = (self.kernel.avx2(), self.kernel.avx512());
        rgb.clear();
        rgb.resize(w * h * 3, 0.0);
        // Per band, per tile row: the visits front to back (the record's order reversed),
        // each lane's `c += col·w` with the forward's `w = α·T`, `T ← T·(1 − α)`.
        rgb.par_chunks_mut(3 * w * TILE_SIZE)
            .enumerate()
            .for_each(|(ty, band)| {
                let rows = band.len() / (3 * w);
                for tx in 0..bins.tiles_x {
                    let t = ty * bins.tiles_x + tx;
                    let (x0, cols) = (tx * TILE_SIZE, TILE_SIZE.min(w - tx * TILE_SIZE));
                    for row in 0..rows {
                        let r = t * TILE_SIZE + row;
                        #[cfg(target_arch = "x86_64")]
                        let c = if avx512 {
                            // SAFETY: `avx512` only when the CPU has AVX-512F.
                            unsafe { self.replay_row_avx512(r, colors) }
                        } else if avx2 {
                            // SAFETY: `avx2` only when the CPU has AVX2.
                            unsafe { self.replay_row_avx2(r, colors) }
                        } else {
                            self.replay_row(r, colors)
                        };
                        #[cfg(not(target_arch = "x86_64"))]
                        let c = self.replay_row(r, colors);
                        for l in 0..cols {
                            let i = (ty * TILE_SIZE + row) * w + x0 + l;
                            let out = &mut band[3 * (row * w + x0 + l)..][..3];
                            let t = self.final_t[i];
                            for ch in 0..3 {
                                let c = c[ch][l];
                                out[ch] = if apply { c + t * bg[ch] } else { c };
                            }
                        }
                    }
                }
            });
        Ok(())
    }

    /// Backward of the blend for `v_rgb`: per-Gaussian gradients of the (clamped) splat
    /// colours and the background gradient, into `ws`; the same bits as the full
    /// backward's splat colour gradients.
    pub fn color_backward(&self, v_rgb: &[f32], ws: &mut FrozenWork) -> Result<()> {
        let final_t = &self.final_t;
        if v_rgb.len() != final_t.len() * 3 {
            return Err(Error::invalid(
                "rgb gradient size differs from the recorded camera",
            ));
        }
        let bins = &self.bins;
        let (w, h) = (self.cam.width as usize, self.cam.height as usize);
        ws.bands.resize_with(bins.tiles_y, Default::default);
        #[cfg(target_arch = "x86_64")]
        let (avx2, avx512) = (self.kernel.avx2(), self.kernel.avx512());
        // Per band, in the full backward's orders: background in (tile, row, pixel) order,
        // then the visits into their (tile, splat) lane-pair accumulators, reduced per tile
        // into the band's intersection range.
        ws.bands
            .par_iter_mut()
            .enumerate()
            .for_each(|(ty, BandWork { inter, lanes, bg })| {
                let first = bins.offsets[ty * bins.tiles_x];
                let last = bins.offsets[(ty + 1) * bins.tiles_x];
                let y0 = ty * TILE_SIZE;
                let rows = TILE_SIZE.min(h - y0);
                *bg = [0f64; 3];
                for tx in 0..bins.tiles_x {
                    let (x0, cols) = (tx * TILE_SIZE, TILE_SIZE.min(w - tx * TILE_SIZE));
                    for row in 0..rows {
                        for l in 0..cols {
                            let i = (y0 + row) * w + x0 + l;
                            for (ch, b) in bg.iter_mut().enumerate() {
                                *b += (final_t[i] * v_rgb[3 * i + ch]) as f64;
                            }
                        }
                    }
                }
                inter.clear();
                inter.resize(last - first, [0f32; 3]);
                for tx in 0..bins.tiles_x {
                    let t = ty * bins.tiles_x + tx;
                    let (x0, cols) = (tx * TILE_SIZE, TILE_SIZE.min(w - tx * TILE_SIZE));
                    // A row's first visit (back to front) is its deepest list position.
                    let n = (0..rows)
                        .filter_map(|row| {
                            let r = t * TILE_SIZE + row;
                            (self.row_visits[r] < self.row_visits[r + 1]).then(|| {
                                self.visit_k[self.row_visits[r]] as usize - bins.offsets[t] + 1
                            })
                        })
                        .max()
                        .unwrap_or(0);
                    if lanes.len() < n {
                        lanes.resize(n, [[0.0; HALF]; 3]);
                    }
                    let mut used = 0usize;
                    for row in 0..rows {
                        let r = t * TILE_SIZE + row;
                        let i0 = (y0 + row) * w + x0;
                        let mut tt = [0f32; LANES];
                        tt[..cols].copy_from_slice(&final_t[i0..i0 + cols]);
                        let mut a0 = self.row_alpha[r];
                        for v in self.row_visits[r]..self.row_visits[r + 1] {
                            let pos = self.visit_k[v] as usize - bins.offsets[t];
                            used = used.max(pos + 1);
                            let [first, count] = self.visit_lanes[v].map(usize::from);
                            let alphas = &self.alpha[a0..a0 + count];
                            #[cfg(target_arch = "x86_64")]
                            let fac = if avx512 {
                                // SAFETY: `avx512` only when the CPU has AVX-512F.
                                unsafe { recover_visit_avx512(&mut tt, alphas, first) }
                            } else if avx2 {
                                // SAFETY: `avx2` only when the CPU has AVX2.
                                unsafe { recover_visit_avx2(&mut tt, alphas, first) }
                            } else {
                                recover_visit(&mut tt, alphas, first)
                            };
                            #[cfg(not(target_arch = "x86_64"))]
                            let fac = recover_visit(&mut tt, alphas, first);
                            a0 += count;
                            #[cfg(target_arch = "x86_64")]
                            if avx2 && cols == LANES {
                                let rgb: &[f32; 3 * LANES] = v_rgb[3 * i0..3 * (i0 + LANES)]
                                    .try_into()
                                    .expect("16 pixels");
                                // SAFETY: `avx2` only when the CPU has AVX2 (`Kernel::avx2`).
                                unsafe { visit_avx2(&mut lanes[pos], &fac, rgb) };
                                continue;
                            }
                            for (ch, acc) in lanes[pos].iter_mut().enumerate() {
                                let mut c = [0f32; LANES];
                                for l in 0..cols {
                                    c[l] = fac[l] * v_rgb[3 * (i0 + l) + ch];
                                }
                                add_pairs(acc, &c);
                            }
                        }
                    }
                    let start = bins.offsets[t] - first;
                    for (acc, out) in lanes[..used].iter_mut().zip(&mut inter[start..]) {
                        *out = acc.map(|a| sum8(&a));
                        *acc = [[0.0; HALF]; 3];
                    }
                }
            });
        ws.v_color.clear();
        ws.v_color.resize(self.geometry.len(), [0.0; 3]);
        let mut bg = [0f64; 3];
        let mut k = 0;
        for BandWork { inter, bg: b, .. } in &ws.bands {
            for c in inter {
                let g = &mut ws.v_color[bins.ids[k] as usize];
                for ch in 0..3 {
                    g[ch] += c[ch];
                }
                k += 1;
            }
            for ch in 0..3 {
                bg[ch] += b[ch];
            }
        }
        ws.background = bg.map(|v| v as f32);
        Ok(())
    }

    /// The SH-rest gradient of Gaussians `first/row ..` (`row = (K−1)·3` values each) into
    /// `out` (whole Gaussians), from the render and blend backward recorded in `ws` ([`render_rgb_with`],
    /// [`color_backward`]); the same bits as the full backward. Made to be called per
    /// chunk by [`crate::train::adam::Adam::step_with`].
    ///
    /// [`render_rgb_with`]: FrozenBlend::render_rgb_with
    /// [`color_backward`]: FrozenBlend::color_backward
    pub fn sh_rest_grad(&self, ws: &FrozenWork, first: usize, out: &mut [f32]) {
        let g = &*self.geometry;
        assert_eq!(
            ws.record, self.id,
            "the work buffers belong to another record"
        );
        let k_used = num_coeffs(self.plan.sh_degree) - 1;
        let row = g.rest_per_channel() * 3;
        for (j, o) in out.chunks_exact_mut(row).enumerate() {
            let i = first / row + j;
            o.fill(0.0);
            if !self.visible[i] {
                continue;
            }
            let basis = sh_view_basis(g, i, &self.cam, self.plan.sh_degree);
            let (raw, vc) = (ws.raw[i], ws.v_color[i]);
            let v_sh: [f32; 3] = std::array::from_fn(|ch| if raw[ch] > 0.0 { vc[ch] } else { 0.0 });
            for k in 0..k_used {
                for ch in 0..3 {
                    o[k * 3 + ch] = basis[k + 1] * v_sh[ch];
                }
            }
        }
    }

    /// SH (and background) gradients for `v_rgb`: the same bits as the full backward with
    /// these groups. Geometry groups are refused. [`FrozenBlend::color_backward`] and
    /// [`FrozenBlend::sh_rest_grad`] are the fine-tune's allocation-free path.
    pub fn backward_sh(
        &self,
        scene: &Gaussians,
        v_rgb: &[f32],
        groups: &GradGroups,
    ) -> Result<Gradients> {
        if groups.geometry() {
            return Err(Error::invalid(
                "a frozen-geometry record gives only SH and background gradients",
            ));
        }
        self.check(scene)?;
        let mut ws = FrozenWork::default();
        self.color_backward(v_rgb, &mut ws)?;
        let splats: Vec<SplatGrad> = ws
            .v_color
            .iter()
            .map(|&color| SplatGrad {
                color,
                ..SplatGrad::default()
            })
            .collect();
        // Of the projection, only "culled or not" (the record's visibility) and the colours
        // (the clamp) are read.
        self.colors(scene, &mut ws);
        let fwd = Projected {
            splats: ws
                .colors
                .iter()
                .map(|&color| Splat {
                    color,
                    ..Splat::default()
                })
                .collect(),
            radii: self
                .visible
                .iter()
                .map(|&v| if v { [1, 1] } else { [0, 0] })
                .collect(),
        };
        let mut grads = project_backward(
            scene,
            &self.cam,
            &fwd,
            &self.plan,
            groups,
            &splats,
            self.kernel,
        );
        if groups.background {
            grads.background = ws.background;
        }
        Ok(grads)
    }
}

/// The lanes `[first, first + len)` as a 16-lane mask (`len ≤ 16 − first`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn run_mask(first: usize, len: usize) -> u16 {
    (((1u32 << len) - 1) << first) as u16
}

/// One visit of the SH backward's walk, back to front: for each lane of the run that
/// blended (α > 0), [`recover`] steps its transmittance `tt` back over the splat and gives
/// the splat's weight; the weights, 0 elsewhere.
#[inline(always)]
fn recover_visit(tt: &mut [f32; LANES], alphas: &[f32], first: usize) -> [f32; LANES] {
    let mut fac = [0f32; LANES];
    for (j, &a) in alphas.iter().enumerate() {
        if a > 0.0 {
            let l = first + j;
            let (_, tn, f) = recover(tt[l], a);
            fac[l] = f;
            tt[l] = tn;
        }
    }
    fac
}

/// [`recover_visit`] eight lanes per instruction, the run's α placed in its lanes (0
/// elsewhere): [`recover`]'s operations lane for lane, the weights masked to +0.0 where a
/// lane does not blend.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn recover_visit_avx2(tt: &mut [f32; LANES], alphas: &[f32], first: usize) -> [f32; LANES] {
    use std::arch::x86_64::*;
    let zero = _mm256_setzero_ps();
    let mut a = [0f32; LANES];
    a[first..first + alphas.len()].copy_from_slice(alphas);
    let mut fac = [0f32; LANES];
    for h in 0..2 {
        // SAFETY: `a`, `tt` and `fac` hold 16 f32; `8h + 8 ≤ 16`.
        unsafe {
            let av = _mm256_loadu_ps(a.as_ptr().add(8 * h));
            let blends = _mm256_cmp_ps::<_CMP_GT_OQ>(av, zero);
            let t = _mm256_loadu_ps(tt.as_ptr().add(8 * h));
            let den = _mm256_max_ps(
                _mm256_sub_ps(_mm256_set1_ps(1.0), av),
                _mm256_set1_ps(super::composite::RECOVER_EPS),
            );
            let ra = _mm256_div_ps(_mm256_set1_ps(1.0), den);
            let tn = _mm256_mul_ps(t, ra);
            let f = _mm256_mul_ps(av, tn);
            _mm256_storeu_ps(fac.as_mut_ptr().add(8 * h), _mm256_and_ps(blends, f));
            _mm256_storeu_ps(tt.as_mut_ptr().add(8 * h), _mm256_blendv_ps(t, tn, blends));
        }
    }
    fac
}

/// [`recover_visit`] sixteen lanes per instruction: [`recover`]'s operations lane for lane
/// (`max_ps(1 − α, ε)` is its select: `a > b ? a : b`), the run's α expanded into its lanes.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn recover_visit_avx512(
    tt: &mut [f32; LANES],
    alphas: &[f32],
    first: usize,
) -> [f32; LANES] {
    use std::arch::x86_64::*;
    let zero = _mm512_setzero_ps();
    let run = run_mask(first, alphas.len());
    let mut fac = [0f32; LANES];
    // SAFETY: the expanding load reads popcount(run) = `alphas.len()` values from the start
    // of `alphas`; `tt` and `fac` hold 16 f32.
    unsafe {
        let a = _mm512_maskz_expandloadu_ps(run, alphas.as_ptr());
        let blends = _mm512_mask_cmp_ps_mask::<_CMP_GT_OQ>(run, a, zero);
        let t = _mm512_loadu_ps(tt.as_ptr());
        let den = _mm512_max_ps(
            _mm512_sub_ps(_mm512_set1_ps(1.0), a),
            _mm512_set1_ps(super::composite::RECOVER_EPS),
        );
        let ra = _mm512_div_ps(_mm512_set1_ps(1.0), den);
        let tn = _mm512_mul_ps(t, ra);
        let f = _mm512_mul_ps(a, tn);
        _mm512_storeu_ps(fac.as_mut_ptr(), _mm512_maskz_mov_ps(blends, f));
        _mm512_storeu_ps(tt.as_mut_ptr(), _mm512_mask_mov_ps(t, blends, tn));
    }
    fac
}

/// One full-width visit of [`FrozenBlend::color_backward`] in AVX2: per channel, the 16
/// contributions `fac[l]·v_rgb[3l + ch]` and [`add_pairs`] (`acc_j += c_j + c_{j+8}`), the
/// scalar loop's operations one for one. `rgb` (16 interleaved pixels) is split into
/// channels by blends and a lane permutation (data movement only).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::needless_range_loop)] // h indexes parallel register arrays
unsafe fn visit_avx2(acc: &mut Lanes, fac: &[f32; LANES], rgb: &[f32; 3 * LANES]) {
    use std::arch::x86_64::*;
    let ld = |a: &[f32], o: usize| -> __m256 {
        // SAFETY: `a[o..o + 8]` (bounds-checked) holds 8 f32.
        unsafe { _mm256_loadu_ps(a[o..o + 8].as_ptr()) }
    };
    let idx = |i: [i32; 8]| _mm256_setr_epi32(i[0], i[1], i[2], i[3], i[4], i[5], i[6], i[7]);
    // 8 pixels r0 g0 b0 r1 … b7 in a0, a1, a2: lanes of channel ch come from a0, a1, a2 in
    // a rotating pattern; two blends gather them in one register, a permutation orders them.
    let (pr, pg, pb) = (
        idx([0, 3, 6, 1, 4, 7, 2, 5]),
        idx([1, 4, 7, 2, 5, 0, 3, 6]),
        idx([2, 5, 0, 3, 6, 1, 4, 7]),
    );
    let mut c = [[_mm256_setzero_ps(); 2]; 3];
    for h in 0..2 {
        let (a0, a1, a2) = (ld(rgb, 24 * h), ld(rgb, 24 * h + 8), ld(rgb, 24 * h + 16));
        let r = _mm256_blend_ps::<0x24>(_mm256_blend_ps::<0x92>(a0, a1), a2);
        let g = _mm256_blend_ps::<0x49>(_mm256_blend_ps::<0x24>(a0, a1), a2);
        let b = _mm256_blend_ps::<0x92>(_mm256_blend_ps::<0x49>(a0, a1), a2);
        let f = ld(fac, 8 * h);
        c[0][h] = _mm256_mul_ps(f, _mm256_permutevar8x32_ps(r, pr));
        c[1][h] = _mm256_mul_ps(f, _mm256_permutevar8x32_ps(g, pg));
        c[2][h] = _mm256_mul_ps(f, _mm256_permutevar8x32_ps(b, pb));
    }
    for (a, c) in acc.iter_mut().zip(&c) {
        let p = a.as_mut_ptr();
        // SAFETY: `a` holds 8 f32.
        unsafe {
            let sum = _mm256_add_ps(_mm256_loadu_ps(p), _mm256_add_ps(c[0], c[1]));
            _mm256_storeu_ps(p, sum);
        }
    }
}

/// Reusable buffers of one frozen-blend iteration (render, blend backward, SH gradient):
/// after the first iteration nothing is allocated.
#[derive(Default)]
pub struct FrozenWork {
    /// The record whose render filled `raw`/`colors` (0: none).
    record: u64,
    raw: Vec<[f32; 3]>,
    colors: Vec<[f32; 3]>,
    v_color: Vec<[f32; 3]>,
    background: [f32; 3],
    bands: Vec<BandWork>,
}

/// Per-splat colour lane-pair accumulators of one (tile, splat) entry.
type Lanes = [[f32; HALF]; 3];

/// Work buffers of one band of [`FrozenBlend::color_backward`].
#[derive(Default)]
struct BandWork {
    /// Per intersection of the band, the reduced colour gradient.
    inter: Vec<[f32; 3]>,
    /// The current tile's accumulators, by list position (all +0.0 between tiles).
    lanes: Vec<Lanes>,
    bg: [f64; 3],
}

impl FrozenWork {
    /// The background gradient of the last [`FrozenBlend::color_backward`].
    pub fn background_grad(&self) -> [f32; 3] {
        self.background
    }
}

/// Record identities (never 0), so a work buffer is never used with another record.
static NEXT_RECORD: AtomicU64 = AtomicU64::new(1);
