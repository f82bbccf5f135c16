//! Structural similarity as INRIA 3DGS trains with it (`utils/loss_utils.py`): an 11×11
//! Gaussian window with σ = 1.5 (normalized), zero padding of 5, `C1 = 0.01²`,
//! `C2 = 0.03²`, per channel, mean over all pixels and channels. Computed in f64 with a
//! separable window (INRIA convolves in f32 with the 2D outer product; the values agree to
//! f32 rounding), so the result does not depend on the thread count or the platform.
//!
//! Gradient: with `μ = G⊛x`, `E_xx = G⊛x²`, `E_xy = G⊛(x·y)` and `S(μx, μy, E_xx, E_yy, E_xy)`
//! per pixel, `dS̄/dx = (G⊛∂S/∂μx + 2x·G⊛∂S/∂E_xx + y·G⊛∂S/∂E_xy) / N`, the window being
//! symmetric so that its adjoint (with zero padding) is itself.

use crate::raster::kernel::Isa;
use rayon::prelude::*;

/// Window size and standard deviation (INRIA `ssim(window_size=11)`, `gaussian(11, 1.5)`).
pub const SSIM_WINDOW: usize = 11;
pub const SSIM_SIGMA: f64 = 1.5;
/// Stabilizers for unit-range images.
pub const SSIM_C1: f64 = 0.01 * 0.01;
pub const SSIM_C2: f64 = 0.03 * 0.03;

fn kernel() -> [f64; SSIM_WINDOW] {
    let mut k = [0.0; SSIM_WINDOW];
    let half = (SSIM_WINDOW / 2) as f64;
    for (i, v) in k.iter_mut().enumerate() {
        let d = i as f64 - half;
        *v = (-(d * d) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let s: f64 = k.iter().sum();
    k.map(|v| v / s)
}

/// Window radius (taps `t = 0..11` sit at offsets `t − 5`).
const RADIUS: usize = SSIM_WINDOW / 2;

/// `out[x] = Σ_t k[t]·src[t][x]`, the taps in ascending `t` accumulated from 0, separate
/// multiply and add (never fused): the one definition of a blur output. The loop over `x`
/// is innermost once the eleven taps are unrolled, so it vectorizes without changing any
/// element's order of operations; compiled per instruction set by [`taps_for`].
///
/// Zero padding is a zero source row (vertical) or zeros beside the row (horizontal): the
/// accumulator starts at +0.0 and so is never −0.0, and adding `k·0 = +0.0` leaves any
/// other value unchanged — the same bits as skipping the out-of-range taps.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // t and j index the kernel, rows and block together
fn taps(src: &[&[f64]; SSIM_WINDOW], k: &[f64; SSIM_WINDOW], out: &mut [f64]) {
    let n = out.len();
    let s: [&[f64]; SSIM_WINDOW] = std::array::from_fn(|t| &src[t][..n]);
    // Blocks of TAP_BLOCK outputs keep that many independent sums in flight (one sum's
    // chain of eleven dependent adds would leave the adder idle), then the tail one by one.
    let full = n - n % TAP_BLOCK;
    for (b, o) in out[..full].chunks_exact_mut(TAP_BLOCK).enumerate() {
        let x0 = b * TAP_BLOCK;
        let mut acc = [0.0; TAP_BLOCK];
        for t in 0..SSIM_WINDOW {
            let row = &s[t][x0..x0 + TAP_BLOCK];
            for j in 0..TAP_BLOCK {
                acc[j] += k[t] * row[j];
            }
        }
        o.copy_from_slice(&acc);
    }
    for x in full..n {
        let mut acc = 0.0;
        for t in 0..SSIM_WINDOW {
            acc += k[t] * s[t][x];
        }
        out[x] = acc;
    }
}

/// Outputs [`taps`] computes together: four AVX-512F registers of f64.
const TAP_BLOCK: usize = 32;

/// [`taps`] compiled for `isa`.
fn taps_for(isa: Isa, src: &[&[f64]; SSIM_WINDOW], k: &[f64; SSIM_WINDOW], out: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2(src: &[&[f64]; SSIM_WINDOW], k: &[f64; SSIM_WINDOW], out: &mut [f64]) {
            taps(src, k, out)
        }
        #[target_feature(enable = "avx512f")]
        fn avx512(src: &[&[f64]; SSIM_WINDOW], k: &[f64; SSIM_WINDOW], out: &mut [f64]) {
            taps(src, k, out)
        }
        match isa {
            // SAFETY: `isa` comes from `Isa::detect`, which saw the feature.
            Isa::Avx512 => return unsafe { avx512(src, k, out) },
            // SAFETY: as above.
            Isa::Avx2 => return unsafe { avx2(src, k, out) },
            Isa::Baseline => {}
        }
    }
    taps(src, k, out)
}

/// The horizontally blurred rows a vertical pass needs, for a sweep down the image: slot
/// `yy mod 11` holds row `yy`'s `q` quantities (`[slot][q][x]`), so that while output row
/// `y` is made the ring holds rows `y − 5 ..= y + 5` (those inside the image; rows outside
/// read from `zeros`). A few hundred kilobytes at most instead of whole planes: the
/// vertical pass reads each row eleven times while it is in cache.
struct Ring<'z> {
    isa: Isa,
    k: [f64; SSIM_WINDOW],
    /// Width, height and quantities per row.
    w: usize,
    h: usize,
    q: usize,
    slots: Vec<f64>,
    /// The `q` source rows of one image row, each with `RADIUS` zeros on either side.
    pad: Vec<f64>,
    zeros: &'z [f64],
}

/// The most quantities a [`Ring`] blurs per row (the five moments).
const MAX_Q: usize = 5;

impl<'z> Ring<'z> {
    fn new(isa: Isa, (w, h, q): (usize, usize, usize), zeros: &'z [f64]) -> Self {
        assert!(q <= MAX_Q);
        Ring {
            isa,
            k: kernel(),
            w,
            h,
            q,
            slots: vec![0.0; SSIM_WINDOW * q * w],
            pad: vec![0.0; q * (w + 2 * RADIUS)],
            zeros,
        }
    }

    /// Row `yy` blurred along x into its slot: `fill(yy, rows)` writes its `q` quantities
    /// into `rows` (the padded rows' insides), then each is blurred.
    fn put(&mut self, yy: usize, fill: &mut impl FnMut(usize, &mut [&mut [f64]])) {
        let (w, q, stride) = (self.w, self.q, self.w + 2 * RADIUS);
        let mut inner = self
            .pad
            .chunks_exact_mut(stride)
            .map(|r| &mut r[RADIUS..RADIUS + w]);
        let mut rows: [&mut [f64]; MAX_Q] =
            std::array::from_fn(|_| inner.next().unwrap_or_default());
        fill(yy, &mut rows[..q]);
        let slot = &mut self.slots[(yy % SSIM_WINDOW) * q * w..][..q * w];
        for (dst, row) in slot.chunks_exact_mut(w).zip(self.pad.chunks_exact(stride)) {
            let src = std::array::from_fn(|t| &row[t..t + w]);
            taps_for(self.isa, &src, &self.k, dst);
        }
    }

    /// Quantity `qi` of output row `y` blurred along y into `out` (the ring holds the rows
    /// `y − 5 ..= y + 5` that are inside the image).
    fn vertical(&self, y: usize, qi: usize, out: &mut [f64]) {
        let (w, q) = (self.w, self.q);
        let src = std::array::from_fn(|t| match (y + t).checked_sub(RADIUS) {
            Some(yy) if yy < self.h => &self.slots[((yy % SSIM_WINDOW) * q + qi) * w..][..w],
            _ => self.zeros,
        });
        taps_for(self.isa, &src, &self.k, out)
    }

    /// Output rows `rows` in order: before `each(y, ring)` the ring holds what
    /// [`Ring::vertical`] needs for row `y`. A band blurs the five rows above it and the
    /// five below it too, which its neighbours blur as well (every row's values come from the
    /// same operations on the same inputs, so the bands' bounds do not change any bit).
    fn sweep(
        &mut self,
        rows: std::ops::Range<usize>,
        mut fill: impl FnMut(usize, &mut [&mut [f64]]),
        mut each: impl FnMut(usize, &Self),
    ) {
        for yy in rows.start.saturating_sub(RADIUS)..(rows.start + RADIUS).min(self.h) {
            self.put(yy, &mut fill);
        }
        for y in rows {
            if y + RADIUS < self.h {
                self.put(y + RADIUS, &mut fill);
            }
            each(y, self);
        }
    }
}

/// Per pixel of a row, from the blurred moments `m = [μx, μy, E_xx, E_yy, E_xy]`: the SSIM
/// value into `v` and, with `GRAD`, the derivative planes `dS/dμx` (with the `μx` terms of
/// `σxx`, `σxy` folded in), `dS/dE_xx`, `dS/dE_xy` into `d`. Compiled per instruction set by
/// [`pixels_for`]; the same operations per element at any width.
#[inline(always)]
fn pixels<const GRAD: bool>(m: &[&[f64]; 5], v: &mut [f64], d: &mut [&mut [f64]; 3]) {
    let n = v.len();
    let [mx, my, exx, eyy, exy] = m.map(|r| &r[..n]);
    let [d0, d1, d2] = d;
    let len = if GRAD { n } else { 0 };
    let (d0, d1, d2) = (&mut d0[..len], &mut d1[..len], &mut d2[..len]);
    for p in 0..n {
        let (ux, uy) = (mx[p], my[p]);
        let (sxx, syy, sxy) = (exx[p] - ux * ux, eyy[p] - uy * uy, exy[p] - ux * uy);
        let a1 = 2.0 * ux * uy + SSIM_C1;
        let a2 = 2.0 * sxy + SSIM_C2;
        let b1 = ux * ux + uy * uy + SSIM_C1;
        let b2 = sxx + syy + SSIM_C2;
        v[p] = a1 * a2 / (b1 * b2);
        if GRAD {
            let ds_dsxx = -a1 * a2 / (b1 * b2 * b2);
            let ds_dsxy = 2.0 * a1 / (b1 * b2);
            d0[p] = 2.0 * uy * a2 / (b1 * b2) - 2.0 * ux * a1 * a2 / (b1 * b1 * b2)
                + ds_dsxx * (-2.0 * ux)
                + ds_dsxy * (-uy);
            d1[p] = ds_dsxx;
            d2[p] = ds_dsxy;
        }
    }
}

/// [`pixels`] compiled for `isa`.
fn pixels_for<const GRAD: bool>(isa: Isa, m: &[&[f64]; 5], v: &mut [f64], d: &mut [&mut [f64]; 3]) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2<const G: bool>(m: &[&[f64]; 5], v: &mut [f64], d: &mut [&mut [f64]; 3]) {
            pixels::<G>(m, v, d)
        }
        #[target_feature(enable = "avx512f")]
        fn avx512<const G: bool>(m: &[&[f64]; 5], v: &mut [f64], d: &mut [&mut [f64]; 3]) {
            pixels::<G>(m, v, d)
        }
        match isa {
            // SAFETY: `isa` comes from `Isa::detect`, which saw the feature.
            Isa::Avx512 => return unsafe { avx512::<GRAD>(m, v, d) },
            // SAFETY: as above.
            Isa::Avx2 => return unsafe { avx2::<GRAD>(m, v, d) },
            Isa::Baseline => {}
        }
    }
    pixels::<GRAD>(m, v, d)
}

/// Mean SSIM of `x` against `y` (interleaved, `c` channels) and, if `grad`, dSSIM/dx.
pub fn ssim(
    x: &[f32],
    y: &[f32],
    w: usize,
    h: usize,
    c: usize,
    grad: bool,
) -> (f64, Option<Vec<f32>>) {
    ssim_impl(x, y, w, h, c, grad, None)
}

/// The SSIM map: per pixel, the mean over channels of the windowed SSIM that [`ssim`]
/// averages (so `ssim` is the mean of this map over all pixels, up to summation order).
/// For scores over a pixel subset (existing / extrapolated pixels, SPEC.md §20.7).
pub fn ssim_map(x: &[f32], y: &[f32], w: usize, h: usize, c: usize) -> Vec<f64> {
    let mut map = vec![0.0; w * h];
    ssim_impl(x, y, w, h, c, false, Some(&mut map));
    map
}

/// How the mean SSIM treats the image border (a convention of the library computing it;
/// SPEC.md §13). The values inside are the same; the border moves the mean by ≈ 1e-3.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Border {
    /// Zero padding by the window's radius, the mean over every pixel: INRIA's, what
    /// training uses ([`ssim`]).
    Zero,
    /// The mean over the pixels whose window lies inside the image (pytorch-msssim).
    Valid,
    /// The images mirrored by the window's radius (the edge pixel not repeated, PyTorch's
    /// `"reflect"`), the mean over every pixel (torchmetrics 1.9).
    Reflect,
}

/// The mean SSIM under `border` and the map it averages (per pixel, the mean over
/// channels), with the map's (rows, columns): the image's, or 10 fewer each for
/// [`Border::Valid`]. [`Border::Valid`] and [`Border::Reflect`] need images larger than
/// 10×10 (an error otherwise).
pub fn ssim_border(
    x: &[f32],
    y: &[f32],
    (w, h, c): (usize, usize, usize),
    border: Border,
) -> crate::error::Result<(f64, Vec<f64>, [usize; 2])> {
    let r = RADIUS;
    if w * h * c == 0 || x.len() != w * h * c || y.len() != x.len() {
        return Err(crate::error::Error::invalid(format!(
            "SSIM: {} and {} values for {w}x{h}x{c} images",
            x.len(),
            y.len()
        )));
    }
    if border != Border::Zero && (h <= 2 * r || w <= 2 * r) {
        return Err(crate::error::Error::invalid(format!(
            "SSIM: this border needs images larger than {0}x{0}, got {w}x{h}",
            2 * r
        )));
    }
    // The map over rows and columns [r0, r0 + n) of a map `ww` wide, and its mean.
    let inner = |map: &[f64], ww: usize, r0: usize, (rows, cols): (usize, usize)| {
        let m: Vec<f64> = (r0..r0 + rows)
            .flat_map(|i| map[i * ww + r0..i * ww + r0 + cols].iter().copied())
            .collect();
        (m.iter().sum::<f64>() / m.len() as f64, m)
    };
    Ok(match border {
        Border::Zero => (
            ssim(x, y, w, h, c, false).0,
            ssim_map(x, y, w, h, c),
            [h, w],
        ),
        Border::Valid => {
            let (v, m) = inner(&ssim_map(x, y, w, h, c), w, r, (h - 2 * r, w - 2 * r));
            (v, m, [h - 2 * r, w - 2 * r])
        }
        Border::Reflect => {
            let (px, py) = (reflect_pad(x, (w, h, c), r), reflect_pad(y, (w, h, c), r));
            let map = ssim_map(&px, &py, w + 2 * r, h + 2 * r, c);
            let (v, m) = inner(&map, w + 2 * r, r, (h, w));
            (v, m, [h, w])
        }
    })
}

/// `img` with `r` mirrored pixels around it (the edge pixel not repeated; `r < w, h`).
fn reflect_pad(img: &[f32], (w, h, c): (usize, usize, usize), r: usize) -> Vec<f32> {
    let mirror = |i: usize, n: usize| -> usize {
        // i indexes the padded axis: i − r, reflected into [0, n).
        let j = i as isize - r as isize;
        let n = n as isize;
        (if j < 0 {
            -j
        } else if j >= n {
            2 * (n - 1) - j
        } else {
            j
        }) as usize
    };
    let mut out = Vec::with_capacity((w + 2 * r) * (h + 2 * r) * c);
    for i in 0..h + 2 * r {
        let si = mirror(i, h);
        for j in 0..w + 2 * r {
            let sj = mirror(j, w);
            out.extend_from_slice(&img[(si * w + sj) * c..(si * w + sj + 1) * c]);
        }
    }
    out
}

fn ssim_impl(
    x: &[f32],
    y: &[f32],
    w: usize,
    h: usize,
    c: usize,
    grad: bool,
    map: Option<&mut [f64]>,
) -> (f64, Option<Vec<f32>>) {
    ssim_with(Isa::detect(), x, y, (w, h, c), grad, map)
}

/// [`ssim_impl`] with the row kernels compiled for `isa`, in as many bands of rows as the
/// rayon pool has threads (at least [`BAND_ROWS`] rows each; the bands change no bit).
fn ssim_with(
    isa: Isa,
    x: &[f32],
    y: &[f32],
    dims: (usize, usize, usize),
    grad: bool,
    map: Option<&mut [f64]>,
) -> (f64, Option<Vec<f32>>) {
    let bands = rayon::current_num_threads().min(dims.1.div_ceil(BAND_ROWS));
    ssim_in_bands(isa, bands.max(1), x, y, dims, grad, map)
}

/// Rows a band has at least: a band re-blurs along x the five rows above it and the five
/// below it that its neighbours blur too, so a band should be several times that.
const BAND_ROWS: usize = 32;

/// [`ssim_with`] in `bands` bands of rows, each swept down by a [`Ring`] on its own task.
/// Three passes: (1) per band and channel, the horizontal blur of the 5 moments
/// (`x, y, x², y², xy`) into the ring, their vertical blur and the per-pixel SSIM and
/// derivative planes; (2) the mean in channel-then-pixel order (f64, sequential); with the
/// gradient, (3) per band and channel the horizontal and vertical blur of the derivative
/// planes, combined into `dS̄/dx` per value. Every value comes from the same operations on
/// the same inputs whatever the bands (and the thread count).
#[allow(clippy::too_many_arguments)]
fn ssim_in_bands(
    isa: Isa,
    bands: usize,
    x: &[f32],
    y: &[f32],
    (w, h, c): (usize, usize, usize),
    grad: bool,
    map: Option<&mut [f64]>,
) -> (f64, Option<Vec<f32>>) {
    assert_eq!(x.len(), w * h * c);
    assert_eq!(y.len(), w * h * c);
    let n = (w * h * c) as f64;
    if x.is_empty() {
        return (0.0 / n, grad.then(Vec::new));
    }
    let band = h.div_ceil(bands);
    // The calling thread's buffers of the last call, resized: every value of each is
    // written below before it is read, so none is cleared (a training loop called this
    // with megabytes of fresh zeroed memory every iteration, serially).
    let mut work = WORK.with_borrow_mut(std::mem::take);
    let Work {
        zeros,
        values,
        deriv,
    } = &mut work;
    zeros.clear();
    zeros.resize(w, 0.0);
    let zeros = &zeros[..];
    // Channel `ch` of pixel row `yy` of an interleaved image, in f64 (exact).
    let channel = |img: &[f32], yy: usize, ch: usize, dst: &mut [f64]| {
        let src = &img[yy * w * c..(yy + 1) * w * c];
        for (d, px) in dst.iter_mut().zip(src.chunks_exact(c)) {
            *d = px[ch] as f64;
        }
    };
    // (1) The SSIM map `[y][ch][x]` and the derivative planes `[y][3·ch + j][x]`.
    values.resize(h * c * w, 0.0);
    deriv.resize(if grad { h * 3 * c * w } else { 0 }, 0.0);
    let (values, deriv) = (&mut values[..h * c * w], &mut deriv[..]);
    let task = |b: usize, vals: &mut [f64], ders: &mut [f64]| {
        let y0 = b * band;
        let rows = y0..(y0 + band).min(h);
        let mut ring = Ring::new(isa, (w, h, 5), zeros);
        let mut moments = vec![0.0; 5 * w];
        for ch in 0..c {
            // Quantities x, y, x², y², x·y of channel `ch`.
            let fill = |yy: usize, q: &mut [&mut [f64]]| {
                let [a, b, aa, bb, ab] = q else {
                    unreachable!("five moments")
                };
                channel(x, yy, ch, a);
                channel(y, yy, ch, b);
                for i in 0..w {
                    (aa[i], bb[i], ab[i]) = (a[i] * a[i], b[i] * b[i], a[i] * b[i]);
                }
            };
            ring.sweep(rows.clone(), fill, |row, ring| {
                for (i, m) in moments.chunks_exact_mut(w).enumerate() {
                    ring.vertical(row, i, m);
                }
                let m: [&[f64]; 5] = std::array::from_fn(|i| &moments[i * w..(i + 1) * w]);
                let j = row - y0;
                let v = &mut vals[(j * c + ch) * w..(j * c + ch + 1) * w];
                if grad {
                    let base = (j * 3 * c + 3 * ch) * w;
                    let (d0, rest) = ders[base..base + 3 * w].split_at_mut(w);
                    let (d1, d2) = rest.split_at_mut(w);
                    pixels_for::<true>(isa, &m, v, &mut [d0, d1, d2]);
                } else {
                    pixels_for::<false>(isa, &m, v, &mut [&mut [], &mut [], &mut []]);
                }
            });
        }
    };
    if grad {
        values
            .par_chunks_mut(band * c * w)
            .zip(deriv.par_chunks_mut(band * 3 * c * w))
            .enumerate()
            .for_each(|(b, (vals, ders))| task(b, vals, ders));
    } else {
        values
            .par_chunks_mut(band * c * w)
            .enumerate()
            .for_each(|(b, vals)| task(b, vals, &mut []));
    }
    // (2) The mean, channel by channel in pixel order; the map's mean over channels.
    let mut total = 0.0;
    let mut map = map;
    for ch in 0..c {
        for row in 0..h {
            let v = &values[(row * c + ch) * w..(row * c + ch + 1) * w];
            for (col, &s) in v.iter().enumerate() {
                total += s;
                if let Some(m) = map.as_deref_mut() {
                    m[row * w + col] += s / c as f64;
                }
            }
        }
    }
    let g = grad.then(|| {
        // (3) The derivative planes blurred along x, then y, and combined.
        let qd = 3 * c;
        let deriv = &deriv[..];
        let mut g = vec![0f32; x.len()];
        g.par_chunks_mut(band * w * c)
            .enumerate()
            .for_each(|(b, gs)| {
                let y0 = b * band;
                let rows = y0..(y0 + band).min(h);
                let mut ring = Ring::new(isa, (w, h, 3), zeros);
                let (mut blurred, mut xs, mut ys) = (vec![0.0; 3 * w], vec![0.0; w], vec![0.0; w]);
                for ch in 0..c {
                    let fill = |yy: usize, q: &mut [&mut [f64]]| {
                        for (j, dst) in q.iter_mut().enumerate() {
                            let at = (yy * qd + 3 * ch + j) * w;
                            dst.copy_from_slice(&deriv[at..at + w]);
                        }
                    };
                    ring.sweep(rows.clone(), fill, |row, ring| {
                        for (i, bi) in blurred.chunks_exact_mut(w).enumerate() {
                            ring.vertical(row, i, bi);
                        }
                        let (b0, rest) = blurred.split_at(w);
                        let (b1, b2) = rest.split_at(w);
                        channel(x, row, ch, &mut xs);
                        channel(y, row, ch, &mut ys);
                        let grow = &mut gs[(row - y0) * w * c..(row - y0 + 1) * w * c];
                        for col in 0..w {
                            // Vectorizes; the interleaved f32 store does not hold it back.
                            let v = (b0[col] + 2.0 * xs[col] * b1[col] + ys[col] * b2[col]) / n;
                            grow[col * c + ch] = v as f32;
                        }
                    });
                }
            });
        g
    });
    WORK.with_borrow_mut(|w| *w = work);
    (total / n, g)
}

/// The blur alone: the bound of the SSIM term's cost (`benches/roofline.rs`). `rows` output
/// rows of `width` values, each the eleven-tap window over eleven cache-resident source
/// rows, with [`ssim_with`]'s row kernel compiled for this CPU (the same operations, the
/// same tail handling at this width); rows split over the rayon pool in fixed blocks.
/// Returns the outputs written. One SSIM with its gradient blurs `16·c` planes of
/// `width × height` (the five moments and the three derivative planes, along x and y).
#[doc(hidden)]
pub fn bare_blur(width: usize, rows: usize) -> u64 {
    let k = kernel();
    let isa = Isa::detect();
    let blocks = rayon::current_num_threads().max(1);
    let per = rows.div_ceil(blocks);
    (0..blocks)
        .into_par_iter()
        .map(|b| {
            let src: Vec<f64> = (0..width + 2 * RADIUS)
                .map(|i| (i % 7) as f64 * 0.125)
                .collect();
            let mut out = vec![0.0; width];
            let n = ((b + 1) * per).min(rows).saturating_sub(b * per);
            for _ in 0..n {
                let taps = std::array::from_fn(|t| &src[t..t + width]);
                taps_for(isa, &taps, &k, &mut out);
                std::hint::black_box(&mut out);
            }
            (n * width) as u64
        })
        .sum()
}

/// The buffers of [`ssim_with`], kept per thread between calls.
#[derive(Default)]
struct Work {
    zeros: Vec<f64>,
    values: Vec<f64>,
    deriv: Vec<f64>,
}

thread_local! {
    static WORK: std::cell::RefCell<Work> = std::cell::RefCell::default();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Uniform;

    /// One plane blurred as [`ssim_in_bands`] blurs: a [`Ring`] swept down `bands` bands.
    fn blur(isa: Isa, img: &[f64], w: usize, h: usize, bands: usize) -> Vec<f64> {
        let zeros = vec![0.0; w];
        let mut out = vec![f64::NAN; w * h];
        let band = h.div_ceil(bands);
        for (b, chunk) in out.chunks_mut(band * w).enumerate() {
            let mut ring = Ring::new(isa, (w, h, 1), &zeros);
            let fill =
                |y: usize, q: &mut [&mut [f64]]| q[0].copy_from_slice(&img[y * w..(y + 1) * w]);
            ring.sweep(b * band..(b * band + band).min(h), fill, |y, ring| {
                ring.vertical(y, 0, &mut chunk[(y - b * band) * w..][..w])
            });
        }
        out
    }

    /// The separable, vectorized blur equals a direct 2D window sum (f64, any order) to
    /// rounding, including the zero-padded borders.
    #[test]
    fn separable_blur_matches_direct_2d_window() {
        for (w, h) in [(23, 17), (40, 3), (1, 12)] {
            let mut u = Uniform::new(4);
            let img: Vec<f64> = (0..w * h).map(|_| u.unit() as f64).collect();
            let k = kernel();
            for bands in [1, 2, 5] {
                let fast = blur(Isa::detect(), &img, w, h, bands);
                for y in 0..h {
                    for x in 0..w {
                        let mut acc = 0.0;
                        for (ty, ky) in k.iter().enumerate() {
                            for (tx, kx) in k.iter().enumerate() {
                                let (yy, xx) =
                                    (y as isize + ty as isize - 5, x as isize + tx as isize - 5);
                                if (0..h as isize).contains(&yy) && (0..w as isize).contains(&xx) {
                                    acc += ky * kx * img[yy as usize * w + xx as usize];
                                }
                            }
                        }
                        let got = fast[y * w + x];
                        assert!(
                            (got - acc).abs() < 1e-14,
                            "{w}x{h} ({x},{y}), {bands} bands: {got} vs {acc}"
                        );
                    }
                }
            }
        }
    }

    /// The SSIM as first written (session 1): every plane blurred on its own by skipping the
    /// out-of-range taps, one multiply-add pass per tap over a zeroed row, then the
    /// per-pixel formulas in one loop. The reference whose bits [`ssim_with`] must keep.
    fn ssim_reference(
        x: &[f32],
        y: &[f32],
        w: usize,
        h: usize,
        c: usize,
    ) -> (f64, Vec<f32>, Vec<f64>) {
        let k = kernel();
        let r = RADIUS as isize;
        let blur = |plane: &[f64]| -> Vec<f64> {
            let mut tmp = vec![0.0; w * h];
            for (row_out, row_in) in tmp.chunks_exact_mut(w).zip(plane.chunks_exact(w)) {
                for (t, &kv) in k.iter().enumerate() {
                    let off = t as isize - r;
                    for xo in 0..w as isize {
                        if (0..w as isize).contains(&(xo + off)) {
                            row_out[xo as usize] += kv * row_in[(xo + off) as usize];
                        }
                    }
                }
            }
            let mut dst = vec![0.0; w * h];
            for (yo, row_out) in dst.chunks_exact_mut(w).enumerate() {
                for (t, &kv) in k.iter().enumerate() {
                    let yy = yo as isize + t as isize - r;
                    if yy < 0 || yy >= h as isize {
                        continue;
                    }
                    for (o, &v) in row_out.iter_mut().zip(&tmp[yy as usize * w..][..w]) {
                        *o += kv * v;
                    }
                }
            }
            dst
        };
        let np = w * h;
        let n = (np * c) as f64;
        let (mut total, mut map, mut g) = (0.0, vec![0.0; np], vec![0f32; x.len()]);
        for ch in 0..c {
            let a: Vec<f64> = (0..np).map(|p| x[p * c + ch] as f64).collect();
            let b: Vec<f64> = (0..np).map(|p| y[p * c + ch] as f64).collect();
            let prod = |u: &[f64], v: &[f64]| -> Vec<f64> {
                u.iter().zip(v).map(|(u, v)| u * v).collect()
            };
            let (mx, my) = (blur(&a), blur(&b));
            let (exx, eyy, exy) = (
                blur(&prod(&a, &a)),
                blur(&prod(&b, &b)),
                blur(&prod(&a, &b)),
            );
            let mut d = vec![vec![0.0; np]; 3];
            for p in 0..np {
                let (ux, uy) = (mx[p], my[p]);
                let (sxx, syy, sxy) = (exx[p] - ux * ux, eyy[p] - uy * uy, exy[p] - ux * uy);
                let a1 = 2.0 * ux * uy + SSIM_C1;
                let a2 = 2.0 * sxy + SSIM_C2;
                let b1 = ux * ux + uy * uy + SSIM_C1;
                let b2 = sxx + syy + SSIM_C2;
                let v = a1 * a2 / (b1 * b2);
                total += v;
                map[p] += v / c as f64;
                let ds_dsxx = -a1 * a2 / (b1 * b2 * b2);
                let ds_dsxy = 2.0 * a1 / (b1 * b2);
                d[0][p] = 2.0 * uy * a2 / (b1 * b2) - 2.0 * ux * a1 * a2 / (b1 * b1 * b2)
                    + ds_dsxx * (-2.0 * ux)
                    + ds_dsxy * (-uy);
                d[1][p] = ds_dsxx;
                d[2][p] = ds_dsxy;
            }
            let bd: Vec<Vec<f64>> = d.iter().map(|p| blur(p)).collect();
            for p in 0..np {
                let (xs, ys) = (a[p], b[p]);
                g[p * c + ch] = ((bd[0][p] + 2.0 * xs * bd[1][p] + ys * bd[2][p]) / n) as f32;
            }
        }
        (total / n, g, map)
    }

    /// The banded, per-instruction-set, parallel SSIM gives the reference's bits — value,
    /// gradient and map — on sizes below, at and around the window and the tap block, for
    /// 1–3 channels, under every instruction set the CPU has, 1 or 2 threads and any
    /// number of bands (one row each up to more bands than rows).
    #[test]
    fn ssim_keeps_the_reference_bits_in_every_form() {
        let mut isas = vec![Isa::Baseline];
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                isas.push(Isa::Avx2);
            }
            if std::is_x86_feature_detected!("avx512f") {
                isas.push(Isa::Avx512);
            }
        }
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let bits64 = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut u = Uniform::new(11);
        for (w, h, c) in [
            (1, 1, 3),
            (5, 3, 1),
            (11, 11, 3),
            (33, 9, 2),
            (70, 19, 3),
            (37, 29, 3),
            (64, 16, 3),
            (20, 70, 3),
        ] {
            let x: Vec<f32> = (0..w * h * c).map(|_| u.unit()).collect();
            let y: Vec<f32> = x
                .iter()
                .map(|v| (v + 0.4 * (u.unit() - 0.5)).clamp(0.0, 1.0))
                .collect();
            let (s, g, map) = ssim_reference(&x, &y, w, h, c);
            for &isa in &isas {
                for threads in [1, 2] {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .build()
                        .unwrap();
                    // The pool's own bands, then bands of 1 row up to more than there are.
                    for bands in [None, Some(1), Some(2), Some(3), Some(7), Some(h + 1)] {
                        let run = |grad: bool, map: &mut [f64]| match bands {
                            None => ssim_with(isa, &x, &y, (w, h, c), grad, Some(map)),
                            Some(b) => ssim_in_bands(isa, b, &x, &y, (w, h, c), grad, Some(map)),
                        };
                        let (s2, g2, map2) = pool.install(|| {
                            let mut map2 = vec![0.0; w * h];
                            let (s2, g2) = run(true, &mut map2);
                            (s2, g2.unwrap(), map2)
                        });
                        let at = format!("{w}x{h}x{c} {isa:?} {threads} threads, bands {bands:?}");
                        assert_eq!(s.to_bits(), s2.to_bits(), "{at}: {s} vs {s2}");
                        assert_eq!(bits(&g), bits(&g2), "{at}");
                        assert_eq!(bits64(&map), bits64(&map2), "{at}");
                        let mut map3 = vec![0.0; w * h];
                        let (s3, none) = run(false, &mut map3);
                        assert_eq!((s.to_bits(), none), (s3.to_bits(), None), "{at}");
                        assert_eq!(bits64(&map), bits64(&map3), "{at}");
                    }
                }
            }
        }
    }

    #[test]
    fn ssim_of_an_image_with_itself_is_one() {
        let mut u = Uniform::new(1);
        let x: Vec<f32> = (0..17 * 13 * 3).map(|_| u.unit()).collect();
        let (s, _) = ssim(&x, &x, 17, 13, 3, false);
        assert!((s - 1.0).abs() < 1e-12, "{s}");
    }

    /// The analytic gradient against central differences (h = 1e-3 on f32 inputs; the value
    /// is computed in f64, so the difference quotient is accurate to ~1e-9).
    #[test]
    fn ssim_gradient_matches_finite_differences() {
        let (w, h, c) = (14, 11, 2);
        let mut u = Uniform::new(2);
        let x: Vec<f32> = (0..w * h * c).map(|_| u.unit()).collect();
        let y: Vec<f32> = x
            .iter()
            .map(|v| (v + 0.3 * (u.unit() - 0.5)).clamp(0.0, 1.0))
            .collect();
        let (_, g) = ssim(&x, &y, w, h, c, true);
        let g = g.unwrap();
        for i in (0..x.len()).step_by(7) {
            let step = 1.0 / 1024.0; // exact in f32
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i] += step;
            xm[i] -= step;
            let fd = (ssim(&xp, &y, w, h, c, false).0 - ssim(&xm, &y, w, h, c, false).0)
                / (2.0 * step as f64);
            assert!(
                (fd - g[i] as f64).abs() < 1e-7 + 1e-4 * fd.abs(),
                "{i}: {fd} vs {}",
                g[i]
            );
        }
    }
}

#[cfg(test)]
mod border_tests {
    use super::*;

    /// PyTorch's "reflect": the edge pixel is not repeated (`[a b c]` by 1 → `[b a b c b]`).
    #[test]
    fn reflect_padding_mirrors_without_repeating_the_edge() {
        let img: Vec<f32> = (0..6).map(|v| v as f32).collect(); // 3 wide, 2 high, 1 channel
        let p = reflect_pad(&img, (3, 2, 1), 1);
        assert_eq!(
            p,
            [
                4., 3., 4., 5., 4., 1., 0., 1., 2., 1., 4., 3., 4., 5., 4., 1., 0., 1., 2., 1.
            ]
        );
    }

    /// The three borders agree inside; `Valid` is the interior's mean of the zero-padded
    /// map, and too small images are an error for the borders that need a margin.
    #[test]
    fn borders_differ_only_at_the_border() {
        let (w, h, c) = (17, 13, 3);
        let x: Vec<f32> = (0..w * h * c)
            .map(|i| ((i * 37 % 101) as f32) / 100.0)
            .collect();
        let y: Vec<f32> = x.iter().map(|v| (v * 0.9 + 0.05).min(1.0)).collect();
        let (zero, zmap, zs) = ssim_border(&x, &y, (w, h, c), Border::Zero).unwrap();
        let (valid, vmap, vs) = ssim_border(&x, &y, (w, h, c), Border::Valid).unwrap();
        let (_, rmap, rs) = ssim_border(&x, &y, (w, h, c), Border::Reflect).unwrap();
        assert_eq!((zs, vs, rs), ([h, w], [h - 10, w - 10], [h, w]));
        assert!((zero - ssim(&x, &y, w, h, c, false).0).abs() < 1e-15);
        for i in 5..h - 5 {
            for j in 5..w - 5 {
                let z = zmap[i * w + j];
                assert_eq!(vmap[(i - 5) * (w - 10) + j - 5], z);
                assert!((rmap[i * w + j] - z).abs() < 1e-12, "({i}, {j})");
            }
        }
        assert!((valid - vmap.iter().sum::<f64>() / vmap.len() as f64).abs() < 1e-15);
        assert!(ssim_border(&x[..300], &y[..300], (10, 10, 3), Border::Reflect).is_err());
        assert!(ssim_border(&x[..300], &y[..300], (10, 10, 3), Border::Zero).is_ok());
    }
}
