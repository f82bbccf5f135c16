//! Telea's fast-marching inpainting (A. Telea, "An Image Inpainting Technique Based on the
//! Fast Marching Method", JGT 2004), with the arithmetic of OpenCV 5.0's
//! `cv::inpaint(..., INPAINT_TELEA)` (`modules/photo/src/inpaint.cpp`; SPEC.md §19.1) so that results can be
//! compared pixel for pixel.
//!
//! The image is embedded in a grid with a one-pixel border (grid `(i, j)` = image
//! `(i − 1, j − 1)`). Fill pixels are `INSIDE`; their 4-neighbours outside the fill form
//! the band (`T = 0`). Two fast marches follow, both with a priority queue ordered by `T`
//! and then by insertion (FIFO), neighbours visited up, left, down, right:
//!
//! 1. outwards, through the known pixels within the `(2r+1)²` square around the fill, to
//!    give them (negated) distances, so that `∇T` is defined at the band;
//! 2. inwards: each fill pixel reached gets `T` from the eikonal solve (in f64) and its
//!    value from the known pixels `(k, l)` of its radius-`r` disc:
//!    `w = |dst·lev·dir|`, `dst = 1/|r|³`, `lev = 1/(1 + |T_kl − T_ij|)`,
//!    `dir = r·∇T` (`|dir| ≤ 0.01 → 1e-6`); the value is `Σw·I / Σw` plus the unit
//!    vector of the weighted image-gradient term `J` (so at most `√2` levels), rounded
//!    for integer images as OpenCV does (`round_half_even(v + 0.5)`).
//!
//! OpenCV's quirks are kept because they change results: the image gradient at a known
//! pixel is a central difference times 2 (not ½), its stencil is shifted inwards at the
//! first/last image row and column, and masked pixels keep their input values until they
//! are filled (a shifted stencil can read them). Every such point is marked `OpenCV:`.

use crate::error::{Error, Result};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

const KNOWN: u8 = 0;
const BAND: u8 = 1;
const INSIDE: u8 = 2;
const CHANGE: u8 = 3;

/// Largest radius OpenCV accepts (`cvRound(radius)` is clamped to `[1, 100]`).
pub const MAX_RADIUS: i64 = 100;

/// A pixel type the inpainting works on.
pub trait Sample: Copy + Send + Sync {
    /// Integer samples round the fill value (decision boundaries at whole values).
    const INTEGER: bool;
    /// The value as f32 (OpenCV's `(float)` cast).
    fn value(self) -> f32;
    /// `(float)(a − b)`: integer difference for integer types.
    fn diff(a: Self, b: Self) -> f32;
    /// OpenCV's `round_cast`: saturate for integers after `+ 0.5`, identity for floats.
    fn round_cast(v: f32) -> Self;
}

impl Sample for u8 {
    const INTEGER: bool = true;
    fn value(self) -> f32 {
        self as f32
    }
    fn diff(a: Self, b: Self) -> f32 {
        (a as i32 - b as i32) as f32
    }
    fn round_cast(v: f32) -> Self {
        // saturate_cast<uchar>(double): round half to even, then clamp.
        let r = (v as f64 + 0.5).round_ties_even();
        if r.is_nan() {
            0
        } else {
            r.clamp(0.0, 255.0) as u8
        }
    }
}

impl Sample for f32 {
    const INTEGER: bool = false;
    fn value(self) -> f32 {
        self
    }
    fn diff(a: Self, b: Self) -> f32 {
        a - b
    }
    fn round_cast(v: f32) -> Self {
        v
    }
}

/// Inpaint `image` (`height × width × channels`, row-major, interleaved) where `mask` is
/// true, with OpenCV's radius semantics (`radius` rounded half to even, clamped to
/// `[1, 100]`). Any channel count; the channels are filled independently with the same
/// weights.
pub fn inpaint<T: Sample>(
    image: &[T],
    width: usize,
    height: usize,
    channels: usize,
    mask: &[bool],
    radius: f64,
) -> Result<Vec<T>> {
    let range = check(image.len(), width, height, channels, mask, radius)?;
    let mut out = image.to_vec();
    let mut g = Grid::new(width, height, mask);
    if g.band.is_empty() {
        return Ok(out);
    }
    g.march_outwards(range);
    g.fill(&mut out, channels, range, None);
    Ok(out)
}

/// What [`inpaint_traced`] records: each pixel's arrival and, per value (pixel × channel),
/// what a port's value is judged by (SPEC.md §19.1).
#[derive(Debug, Clone)]
pub struct Trace<T> {
    /// The inpainting; with `forced`, every fill value computed from the forced values of
    /// the pixels filled before it.
    pub image: Vec<T>,
    /// `T` per pixel: the fill's arrival times (≥ 0), the band's 0, the known ring's
    /// negated outward distances, and [`FAR`] elsewhere (also on the one-pixel frame
    /// around the image the stencils read).
    pub time: Vec<f32>,
    /// Fill order per pixel (0, 1, …), −1 for a known pixel.
    pub order: Vec<i32>,
    /// Per value: the weighted mean `Σw·I / Σw` of the known disc.
    pub mean: Vec<f32>,
    /// Per value: the gradient term `(Jx + Jy) / |J|`; the value is `mean + term`
    /// (float32), rounded for integer images.
    pub term: Vec<f32>,
    /// Per value: a first-order bound on how far another float arithmetic (summation
    /// order, f32 for f64, fused products, `T` marched in f32) moves `mean + term`.
    pub bound: Vec<f32>,
    /// Per value: the decisions it lies within noise of, so that the algorithm does not
    /// determine it (0: none; else a sum of [`ASIDE_SWITCH`], [`ASIDE_DIRECTION`],
    /// [`ASIDE_ROUNDING`]).
    pub aside: Vec<u8>,
}

/// A neighbour's `|r·∇T|` lies within its noise of the 0.01 switch to the constant 1e-6.
pub const ASIDE_SWITCH: u8 = 1;
/// `|J|` is at most twice its error: the gradient term's direction is undetermined.
pub const ASIDE_DIRECTION: u8 = 2;
/// An integer image's value lies within its bound of a rounding boundary.
pub const ASIDE_ROUNDING: u8 = 4;

/// `T` outside the fill's neighbourhood and on the image's frame (OpenCV's 1e6): a
/// constant every port uses, so it carries no error.
pub const FAR: f32 = 1.0e6;

/// [`inpaint`], recording the [`Trace`] a port is compared with. With `forced` (a port's
/// output, the image's shape), the march is the oracle's but every filled pixel then
/// takes the forced value, so each fill value is judged on the port's own predecessors
/// and an early difference does not propagate. Without it, `image` equals [`inpaint`]'s.
pub fn inpaint_traced<T: Sample>(
    image: &[T],
    width: usize,
    height: usize,
    channels: usize,
    mask: &[bool],
    radius: f64,
    forced: Option<&[T]>,
) -> Result<Trace<T>> {
    let range = check(image.len(), width, height, channels, mask, radius)?;
    if let Some(f) = forced
        && f.len() != image.len()
    {
        return Err(Error::invalid(format!(
            "the forced image has {} values, the image {}",
            f.len(),
            image.len()
        )));
    }
    let n = image.len();
    let mut rec = Record {
        forced,
        order: vec![-1; width * height],
        mean: vec![f32::NAN; n],
        term: vec![f32::NAN; n],
        bound: vec![0.0; n],
        aside: vec![0; n],
    };
    let mut out = image.to_vec();
    let mut g = Grid::new(width, height, mask);
    if !g.band.is_empty() {
        g.march_outwards(range);
        g.fill(&mut out, channels, range, Some(&mut rec));
    }
    if forced.is_some() {
        // `out` ends with the forced values; the trace's image is ours.
        let values = out.chunks_exact_mut(channels).zip(
            rec.mean
                .chunks_exact(channels)
                .zip(rec.term.chunks_exact(channels)),
        );
        for ((px, (mean, term)), &o) in values.zip(&rec.order) {
            if o >= 0 {
                for ((v, m), t) in px.iter_mut().zip(mean).zip(term) {
                    *v = T::round_cast(m + t);
                }
            }
        }
    }
    let cols = width + 2;
    let time = (0..width * height)
        .map(|p| g.t[(p / width + 1) * cols + p % width + 1])
        .collect();
    Ok(Trace {
        image: out,
        time,
        order: rec.order,
        mean: rec.mean,
        term: rec.term,
        bound: rec.bound,
        aside: rec.aside,
    })
}

/// The fill's record for [`inpaint_traced`].
struct Record<'a, T> {
    forced: Option<&'a [T]>,
    order: Vec<i32>,
    mean: Vec<f32>,
    term: Vec<f32>,
    bound: Vec<f32>,
    aside: Vec<u8>,
}

/// Unit roundoff of f32.
const U: f32 = f32::EPSILON / 2.0;

/// How far another port's `T` may lie from ours: the march adds a rounding of relative
/// size ≤ 2u per unit of distance, so ≤ 2u·|T| per step over ≤ max(1, |T|) steps, ×2.
/// [`FAR`] is a constant and exact.
fn time_noise(t: f32) -> f32 {
    if t.abs() >= FAR {
        0.0
    } else {
        4.0 * U * t.abs().max(1.0) * t.abs()
    }
}

/// The arguments' checks; the radius as OpenCV uses it (rounded half to even, clamped to
/// `[1, 100]`).
fn check(
    values: usize,
    width: usize,
    height: usize,
    channels: usize,
    mask: &[bool],
    radius: f64,
) -> Result<i64> {
    if width == 0 || height == 0 || channels == 0 {
        return Err(Error::invalid("inpainting needs a non-empty image"));
    }
    if values != width * height * channels {
        return Err(Error::invalid(format!(
            "the image has {values} values, not {width}x{height}x{channels}"
        )));
    }
    if mask.len() != width * height {
        return Err(Error::invalid(format!(
            "the mask has {} pixels but the image is {width}x{height}",
            mask.len()
        )));
    }
    if !radius.is_finite() {
        return Err(Error::invalid(format!(
            "inpainting radius {radius} is not finite"
        )));
    }
    Ok((radius.round_ties_even() as i64).clamp(1, MAX_RADIUS))
}

/// A queued pixel: smallest `T` first, then first inserted.
type Entry = Reverse<(u32, u32, u32)>;

/// `T ≥ 0` ordered as its bits (the queue never holds negative or NaN times).
fn key(t: f32) -> u32 {
    debug_assert!(t >= 0.0);
    t.to_bits()
}

struct Grid {
    /// Grid size (image + 1-pixel border).
    rows: usize,
    cols: usize,
    /// Flags of the inward march (`INSIDE` on the fill, `KNOWN` elsewhere).
    f: Vec<u8>,
    t: Vec<f32>,
    /// Band pixels in raster order.
    band: Vec<u32>,
    /// The fill, dilated by the radius square, as flags of the outward march.
    mask_grid: Vec<bool>,
}

impl Grid {
    fn new(width: usize, height: usize, mask: &[bool]) -> Grid {
        let (rows, cols) = (height + 2, width + 2);
        let mut mask_grid = vec![false; rows * cols];
        for y in 0..height {
            for x in 0..width {
                mask_grid[(y + 1) * cols + x + 1] = mask[y * width + x];
            }
        }
        let mut f = vec![KNOWN; rows * cols];
        let mut t = vec![FAR; rows * cols];
        let mut band = Vec::new();
        for i in 0..rows {
            for j in 0..cols {
                let p = i * cols + j;
                if mask_grid[p] {
                    f[p] = INSIDE;
                    continue;
                }
                // The 3×3-cross dilation minus the fill, without the grid border.
                let border = i == 0 || j == 0 || i == rows - 1 || j == cols - 1;
                let touches = (i > 0 && mask_grid[p - cols])
                    || (j > 0 && mask_grid[p - 1])
                    || (i + 1 < rows && mask_grid[p + cols])
                    || (j + 1 < cols && mask_grid[p + 1]);
                if touches && !border {
                    band.push(p as u32);
                    t[p] = 0.0;
                }
            }
        }
        Grid {
            rows,
            cols,
            f,
            t,
            band,
            mask_grid,
        }
    }

    /// Eikonal solve from two neighbours (OpenCV's `FastMarching_solve`, in f64).
    fn solve(&self, f: &[u8], p1: usize, p2: usize) -> f32 {
        let (a11, a22) = (self.t[p1] as f64, self.t[p2] as f64);
        let m12 = a11.min(a22);
        let k1 = f[p1] != INSIDE;
        let k2 = f[p2] != INSIDE;
        let sol = match (k1, k2) {
            (true, true) => {
                if (a11 - a22).abs() >= 1.0 {
                    1.0 + m12
                } else {
                    (a11 + a22 + (2.0 - (a11 - a22) * (a11 - a22)).sqrt()) * 0.5
                }
            }
            (true, false) => 1.0 + a11,
            (false, true) => 1.0 + a22,
            (false, false) => 1.0 + m12,
        };
        sol as f32
    }

    /// `min4` of the four quadrant solves at `p` (OpenCV's order).
    fn distance(&self, f: &[u8], p: usize) -> f32 {
        let c = self.cols;
        let (up, down, left, right) = (p - c, p + c, p - 1, p + 1);
        let a = self.solve(f, up, left).min(self.solve(f, down, left));
        let b = self.solve(f, up, right).min(self.solve(f, down, right));
        a.min(b)
    }

    /// March 1: distances of the known pixels within the radius square, negated.
    fn march_outwards(&mut self, range: i64) {
        let (rows, cols) = (self.rows, self.cols);
        // The ring: (2r+1)² square dilation of the fill, minus the fill, minus the band,
        // without the grid border. Separable square dilation.
        let r = range as usize;
        let mut rowwise = vec![false; rows * cols];
        for i in 0..rows {
            for j in 0..cols {
                let (a, b) = (j.saturating_sub(r), (j + r).min(cols - 1));
                rowwise[i * cols + j] = (a..=b).any(|x| self.mask_grid[i * cols + x]);
            }
        }
        let mut f = vec![KNOWN; rows * cols];
        for i in 1..rows - 1 {
            for j in 1..cols - 1 {
                let p = i * cols + j;
                let (a, b) = (i.saturating_sub(r), (i + r).min(rows - 1));
                let dilated = (a..=b).any(|y| rowwise[y * cols + j]);
                if dilated && !self.mask_grid[p] {
                    f[p] = INSIDE;
                }
            }
        }
        let mut heap: BinaryHeap<Entry> = BinaryHeap::new();
        let mut order = 0u32;
        for &p in &self.band {
            f[p as usize] = KNOWN; // the band is not part of the ring
            heap.push(Reverse((key(0.0), order, p)));
            order += 1;
        }
        while let Some(Reverse((_, _, p))) = heap.pop() {
            let p = p as usize;
            f[p] = CHANGE;
            let (ii, jj) = (p / cols, p % cols);
            for (i, j) in neighbours(ii, jj) {
                // OpenCV: `i <= 0 || j <= 0 || i > rows || j > cols` skips; the border is
                // never INSIDE, so only the lower bound matters.
                if i == 0 || j == 0 || i >= rows || j >= cols {
                    continue;
                }
                let q = i * cols + j;
                if f[q] == INSIDE {
                    let d = self.distance(&f, q);
                    self.t[q] = d;
                    f[q] = BAND;
                    heap.push(Reverse((key(d), order, q as u32)));
                    order += 1;
                }
            }
        }
        for (p, &flag) in f.iter().enumerate() {
            if flag == CHANGE {
                self.t[p] = -self.t[p];
            }
        }
    }

    /// March 2: fill the pixels in order of arrival; with `rec`, record each value's
    /// quantities and error bound (and write the forced values, if any, once computed).
    fn fill<T: Sample>(
        &mut self,
        out: &mut [T],
        ch: usize,
        range: i64,
        mut rec: Option<&mut Record<'_, T>>,
    ) {
        let (rows, cols) = (self.rows, self.cols);
        let w = cols - 2;
        let mut heap: BinaryHeap<Entry> = BinaryHeap::new();
        let mut order = 0u32;
        for &p in &self.band {
            heap.push(Reverse((key(0.0), order, p)));
            order += 1;
        }
        let mut filled = 0i32;
        let mut f = std::mem::take(&mut self.f);
        let mut acc = vec![[0f32; 4]; ch]; // Ia, Jx, Jy, s per channel
        // With `rec`, per channel: Σw|I|, Σw(|gx·rx| + |gy·ry|), Σδw(|gx·rx| + |gy·ry|);
        // and per known neighbour δw and its values (for Σδw|I − mean|).
        let mut err = vec![[0f32; 3]; ch];
        let mut neighbour_err: Vec<f32> = Vec::new();
        let at = |out: &[T], y: i64, x: i64, c: usize| -> T {
            // Image coordinates; OpenCV's shifted stencils stay inside for images of at
            // least 2×2 — clamped for the degenerate 1-pixel-wide case.
            let y = y.clamp(0, rows as i64 - 3) as usize;
            let x = x.clamp(0, cols as i64 - 3) as usize;
            out[(y * w + x) * ch + c]
        };
        while let Some(Reverse((_, _, p))) = heap.pop() {
            let p = p as usize;
            f[p] = KNOWN;
            let (ii, jj) = (p / cols, p % cols);
            for (i, j) in neighbours(ii, jj) {
                if i == 0 || j == 0 || i > rows - 1 || j > cols - 1 {
                    continue;
                }
                let q = i * cols + j;
                if f[q] != INSIDE {
                    continue;
                }
                let dist = self.distance(&f, q);
                self.t[q] = dist;
                let t = &self.t;
                let known = |p: usize| f[p] != INSIDE;
                // ∇T and its noise (a port's `T` may differ by `time_noise`).
                let grad_t = |a: usize, b: usize| -> (f32, f32) {
                    // a = the +1 neighbour, b = the −1 neighbour.
                    let (na, nb, nq) = (time_noise(t[a]), time_noise(t[b]), time_noise(t[q]));
                    match (known(a), known(b)) {
                        (true, true) => ((t[a] - t[b]) * 0.5, (na + nb) * 0.5),
                        (true, false) => (t[a] - t[q], na + nq),
                        (false, true) => (t[q] - t[b], nq + nb),
                        (false, false) => (0.0, 0.0),
                    }
                };
                let (gtx, ntx) = grad_t(q + 1, q - 1);
                let (gty, nty) = grad_t(q + cols, q - cols);
                for a in acc.iter_mut() {
                    *a = [0.0, 0.0, 0.0, 1.0e-20];
                }
                let tracing = rec.is_some();
                // Terms summed, a weight at the dir switch.
                let (mut terms, mut at_switch) = (0u32, false);
                if tracing {
                    err.iter_mut().for_each(|e| *e = [0.0; 3]);
                    neighbour_err.clear();
                }
                let (i, j) = (i as i64, j as i64);
                for k in i - range..=i + range {
                    // OpenCV: shifted rows at the first and last image row.
                    let km = k - 1 + (k == 1) as i64;
                    let kp = k - 1 - (k == rows as i64 - 2) as i64;
                    for l in j - range..=j + range {
                        let lm = l - 1 + (l == 1) as i64;
                        let lp = l - 1 - (l == cols as i64 - 2) as i64;
                        if !(k > 0 && l > 0 && k < rows as i64 - 1 && l < cols as i64 - 1) {
                            continue;
                        }
                        let pk = k as usize * cols + l as usize;
                        if !known(pk) || (l - j) * (l - j) + (k - i) * (k - i) > range * range {
                            continue;
                        }
                        let (ry, rx) = ((i - k) as f32, (j - l) as f32);
                        let len2 = rx * rx + ry * ry;
                        let dst = if ch == 1 {
                            // OpenCV (1 channel): float product `|r|²·sqrtf(|r|²)`.
                            (1.0 / (len2 * len2.sqrt()) as f64) as f32
                        } else {
                            // OpenCV (3 channels): `|r|²·sqrt((double)|r|²)` in f64.
                            (1.0 / (len2 as f64 * (len2 as f64).sqrt())) as f32
                        };
                        // OpenCV: `1 + fabs(Δt)` is evaluated in f64 (C's `fabs`), while
                        // the 1-channel `sqrt` above and the final `sqrt` are f32: the
                        // combination that reproduces OpenCV 5.0.0 bit for bit on every
                        // golden case (each other choice changes float results).
                        let lev = (1.0 / (1.0 + (t[pk] - t[q]).abs() as f64)) as f32;
                        let raw_dir = rx * gtx + ry * gty;
                        let switched = (raw_dir.abs() as f64) <= 0.01;
                        let dir = if switched { 0.000001 } else { raw_dir };
                        let wgt = (dst * lev * dir).abs();
                        // The weight's relative error: its roundings, `T`'s noise in `lev`,
                        // and in `dir` (which a switch to the constant removes).
                        let rel_w = if tracing {
                            let n_dir = 4.0 * U * (rx * gtx).abs().max((ry * gty).abs())
                                + rx.abs() * ntx
                                + ry.abs() * nty;
                            at_switch |= (raw_dir.abs() - 0.01).abs() <= n_dir;
                            let lev_noise = time_noise(t[pk]) + time_noise(t[q]);
                            12.0 * U + lev_noise + if switched { 0.0 } else { n_dir / dir.abs() }
                        } else {
                            0.0
                        };
                        terms += 1;
                        if tracing {
                            neighbour_err.push(wgt * rel_w);
                        }
                        let kl_r = known(pk + 1);
                        let kl_l = known(pk - 1);
                        let kd = known(pk + cols);
                        let ku = known(pk - cols);
                        for (c, a) in acc.iter_mut().enumerate() {
                            let v = |y: i64, x: i64| at(out, y, x, c);
                            let gix = match (kl_r, kl_l) {
                                // OpenCV: ×2 on the central difference.
                                (true, true) => T::diff(v(km, lp + 1), v(km, lm - 1)) * 2.0,
                                (true, false) => T::diff(v(km, lp + 1), v(km, lm)),
                                (false, true) => T::diff(v(km, lp), v(km, lm - 1)),
                                (false, false) => 0.0,
                            };
                            let giy = match (kd, ku) {
                                (true, true) => T::diff(v(kp + 1, lm), v(km - 1, lm)) * 2.0,
                                (true, false) => T::diff(v(kp + 1, lm), v(km, lm)),
                                (false, true) => T::diff(v(kp, lm), v(km - 1, lm)),
                                (false, false) => 0.0,
                            };
                            let value = v(k - 1, l - 1).value();
                            a[0] += wgt * value;
                            a[1] -= wgt * (gix * rx);
                            a[2] -= wgt * (giy * ry);
                            a[3] += wgt;
                            if tracing {
                                let e = &mut err[c];
                                let gr = (gix * rx).abs() + (giy * ry).abs();
                                e[0] += wgt * value.abs();
                                e[1] += wgt * gr;
                                e[2] += wgt * rel_w * gr;
                                neighbour_err.push(value);
                            }
                        }
                    }
                }
                let (y, x) = ((i - 1) as usize, (j - 1) as usize);
                let o = (y * w + x) * ch;
                for (c, a) in acc.iter().enumerate() {
                    let [ia, jx, jy, s] = *a;
                    let mean = ia / s;
                    let term = (jx + jy) / ((jx * jx + jy * jy).sqrt() + 1.0e-20);
                    let sat = mean + term;
                    out[o + c] = T::round_cast(sat);
                    if let Some(r) = rec.as_deref_mut() {
                        let e = err[c];
                        // Σ over `terms` products (+ a few roundings each): γ = (n + 4)u.
                        let gamma = (terms + 4) as f32 * U;
                        // Weighted mean: its sums' rounding and its weights' error
                        // (∂(Ia/s)/∂w_k = (I_k − mean)/s).
                        let weights_err: f32 = neighbour_err
                            .chunks_exact(ch + 1)
                            .map(|n| n[0] * (n[1 + c] - mean).abs())
                            .sum();
                        let d_mean = (gamma * e[0] + weights_err) / s;
                        // The unit-vector term moves by ≤ √2·|δJ|/|J|.
                        let d_j = gamma * e[1] + e[2];
                        let j_len = (jx * jx + jy * jy).sqrt();
                        let d_term = if d_j > 0.0 {
                            std::f32::consts::SQRT_2 * d_j / j_len
                        } else {
                            0.0
                        };
                        let bound = 2.0 * (d_mean + d_term + 2.0 * U * sat.abs());
                        let k = o + c;
                        r.mean[k] = mean;
                        r.term[k] = term;
                        r.bound[k] = bound;
                        r.aside[k] = if at_switch { ASIDE_SWITCH } else { 0 }
                            | if d_j > 0.0 && j_len <= 2.0 * d_j {
                                ASIDE_DIRECTION
                            } else {
                                0
                            }
                            | if T::INTEGER && (sat - sat.round()).abs() <= bound {
                                ASIDE_ROUNDING
                            } else {
                                0
                            };
                        if let Some(forced) = r.forced {
                            out[k] = forced[k];
                        }
                    }
                }
                if let Some(r) = rec.as_deref_mut() {
                    r.order[y * w + x] = filled;
                }
                filled += 1;
                f[q] = BAND;
                heap.push(Reverse((key(dist), order, q as u32)));
                order += 1;
            }
        }
        self.f = f;
    }
}

/// Up, left, down, right (OpenCV's visiting order); wrapping `0 − 1` is caught by the
/// callers' bounds checks.
fn neighbours(i: usize, j: usize) -> [(usize, usize); 4] {
    [
        (i.wrapping_sub(1), j),
        (i, j.wrapping_sub(1)),
        (i + 1, j),
        (i, j + 1),
    ]
}

/// Float inpainting of values on an arbitrary scale. Telea's gradient term adds up to `√2`
/// *value units* (OpenCV designed it for 8-bit levels), so float data is first mapped
/// linearly to `[0, span]` (`span` = 255 makes `[0, 1]` images behave like 8-bit ones;
/// depth uses 10⁴), inpainted, and mapped back. Pixels outside the mask keep their input
/// bits exactly.
pub fn inpaint_float(
    values: &[f32],
    width: usize,
    height: usize,
    channels: usize,
    mask: &[bool],
    radius: f64,
    span: f32,
) -> Result<Vec<f32>> {
    if !(span > 0.0 && span.is_finite()) {
        return Err(Error::invalid(format!("span {span} must be positive")));
    }
    let known = values
        .chunks(channels.max(1))
        .zip(mask)
        .filter(|(_, m)| !**m)
        .flat_map(|(v, _)| v.iter().copied());
    let (lo, hi) = known.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !(lo.is_finite() && hi.is_finite()) {
        return Err(Error::invalid("inpainting needs finite known values"));
    }
    let scale = if hi > lo { span / (hi - lo) } else { 1.0 };
    let mapped: Vec<f32> = values
        .chunks(channels.max(1))
        .zip(mask)
        .flat_map(|(v, &m)| {
            v.iter()
                .map(move |&x| if m { 0.0 } else { (x - lo) * scale })
        })
        .collect();
    let filled = inpaint(&mapped, width, height, channels, mask, radius)?;
    let mut out = values.to_vec();
    for (p, &m) in mask.iter().enumerate() {
        if m {
            for c in 0..channels {
                out[p * channels + c] = filled[p * channels + c] / scale + lo;
            }
        }
    }
    Ok(out)
}
