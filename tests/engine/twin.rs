//! The f64 twin of the forward rasterizer, used only by tests and the accuracy bench
//! (`benches/accuracy.rs` includes this file): per pixel over all Gaussians, no tiles, the
//! same rules as the f32 rasterizer (SPEC.md §5) in f64.
use unseen::camera::Camera;
use unseen::gaussian::Gaussians;
use unseen::math::rotation_f64;
use unseen::math::sh::{num_coeffs, sh_basis};
use unseen::rng::Uniform;

/// The forward in f64, per pixel over all Gaussians (no tiles), the same rules as the
/// f32 rasterizer (SPEC.md §5). Returns rgb (interleaved), alpha, D, ED.
pub fn forward64(g: &Gaussians, p: &[f64], cam: &Camera, bg: [f64; 3]) -> [Vec<f64>; 4] {
    forward64_cut(g, p, cam, bg, 1.0 / 255.0, 1e-4)
}

/// [`forward64`] with other cut-offs: the smallest blended α (and opacity cull) and the
/// transmittance stop (`0, 0`: every α > 0 blended, no early stop — exact blending; the
/// twin has no extent cut-off and no σ clamp).
pub fn forward64_cut(
    g: &Gaussians,
    p: &[f64],
    cam: &Camera,
    bg: [f64; 3],
    alpha_threshold: f64,
    transmittance_stop: f64,
) -> [Vec<f64>; 4] {
    let n = g.len();
    let stride = 14 + 3 * g.rest_per_channel();
    let mut splats: Vec<(f64, usize, Splat64)> = Vec::new();
    for i in 0..n {
        if let Some(sp) = project64(
            &p[i * stride..(i + 1) * stride],
            g.sh_degree,
            cam,
            alpha_threshold,
        ) {
            splats.push((sp.z, i, sp));
        }
    }
    splats.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let npix = (cam.width * cam.height) as usize;
    let mut out = [
        vec![0.0; npix * 3],
        vec![0.0; npix],
        vec![0.0; npix],
        vec![0.0; npix],
    ];
    for pi in 0..npix {
        let (px, py) = (
            (pi % cam.width as usize) as f64 + 0.5,
            (pi / cam.width as usize) as f64 + 0.5,
        );
        let (mut tt, mut col, mut dd) = (1.0, [0.0; 3], 0.0);
        for (_, _, s) in &splats {
            let Some(alpha) = s.alpha_at(px, py, alpha_threshold) else {
                continue;
            };
            let nt = tt * (1.0 - alpha);
            if nt <= transmittance_stop {
                break;
            }
            for (c, sc) in col.iter_mut().zip(s.c) {
                *c += sc * alpha * tt;
            }
            dd += s.z * alpha * tt;
            tt = nt;
        }
        for k in 0..3 {
            out[0][pi * 3 + k] = col[k] + tt * bg[k];
        }
        out[1][pi] = 1.0 - tt;
        out[2][pi] = dd;
        out[3][pi] = dd / (1.0 - tt).max(1e-10);
    }
    out
}

/// One Gaussian's splat in f64: screen mean, conic, opacity, colour, camera z.
#[derive(Clone, Copy, Debug)]
pub struct Splat64 {
    pub m: [f64; 2],
    pub con: [f64; 3],
    pub o: f64,
    pub c: [f64; 3],
    pub z: f64,
}

impl Splat64 {
    /// The α the twin blends at pixel centre `(px, py)` (clamped at 0.99), or `None` where
    /// it is skipped (σ < 0, α below the threshold).
    pub fn alpha_at(&self, px: f64, py: f64, alpha_threshold: f64) -> Option<f64> {
        let (dx, dy) = (self.m[0] - px, self.m[1] - py);
        let sigma = 0.5 * (self.con[0] * dx * dx + self.con[2] * dy * dy) + self.con[1] * dx * dy;
        let alpha = (self.o * (-sigma).exp()).min(0.99);
        (sigma >= 0.0 && alpha >= alpha_threshold).then_some(alpha)
    }
}

/// One Gaussian's projection in f64 from its flattened parameters `q` (see [`flatten`]):
/// SPEC.md §5.1's rules, the 2D covariance in the factor form `F·Fᵀ` with the
/// Cauchy–Binet determinant (in f64 the textbook `a·c − b²` loses a needle's thin axis
/// at κ ≈ 10¹⁰ too). `None` behind the near plane, degenerate or below the opacity cull.
pub fn project64(q: &[f64], degree: u32, cam: &Camera, alpha_threshold: f64) -> Option<Splat64> {
    let dot3 = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let r = cam.camera_from_world_rotation();
    let tw = cam.camera_from_world_translation();
    let rcw = [
        [r.x_axis.x, r.y_axis.x, r.z_axis.x],
        [r.x_axis.y, r.y_axis.y, r.z_axis.y],
        [r.x_axis.z, r.y_axis.z, r.z_axis.z],
    ];
    let (w, h) = (cam.width as f64, cam.height as f64);
    let mu = [q[0], q[1], q[2]];
    let [x, y, z] = [
        dot3(rcw[0], mu) + tw.x,
        dot3(rcw[1], mu) + tw.y,
        dot3(rcw[2], mu) + tw.z,
    ];
    // The near plane is the f32 constant (0.01f32 < 0.01).
    if z < f64::from(0.01f32) {
        return None;
    }
    let s = [q[3].exp(), q[4].exp(), q[5].exp()];
    let rot = rotation_f64([q[6], q[7], q[8], q[9]]);
    let qc: [[f64; 3]; 3] = std::array::from_fn(|a| {
        std::array::from_fn(|k| dot3(rcw[a], [rot[0][k], rot[1][k], rot[2][k]]))
    });
    let (fx, fy) = (cam.fx, cam.fy);
    let (tfx, tfy) = (0.5 * w / fx, 0.5 * h / fy);
    let tx = z * (x / z).clamp(-(cam.cx / fx + 0.3 * tfx), (w - cam.cx) / fx + 0.3 * tfx);
    let ty = z * (y / z).clamp(-(cam.cy / fy + 0.3 * tfy), (h - cam.cy) / fy + 0.3 * tfy);
    let j = [
        [fx / z, 0.0, -fx * tx / (z * z)],
        [0.0, fy / z, -fy * ty / (z * z)],
    ];
    let f: [[f64; 3]; 2] = std::array::from_fn(|a| {
        std::array::from_fn(|k| dot3(j[a], [qc[0][k], qc[1][k], qc[2][k]]) * s[k])
    });
    let (a0, b, c0) = (dot3(f[0], f[0]), dot3(f[0], f[1]), dot3(f[1], f[1]));
    let jc = [
        -(j[0][2] * j[1][1]),
        -(j[0][0] * j[1][2]),
        j[0][0] * j[1][1],
    ];
    let ss = [s[1] * s[2], s[0] * s[2], s[0] * s[1]];
    let minors: [f64; 3] =
        std::array::from_fn(|k| ss[k] * dot3([qc[0][k], qc[1][k], qc[2][k]], jc));
    let det = dot3(minors, minors) + 0.3 * (a0 + c0) + 0.09;
    let (a, c) = (a0 + 0.3, c0 + 0.3);
    let o = 1.0 / (1.0 + (-q[10]).exp());
    if det.is_nan() || det <= 0.0 || o < alpha_threshold {
        return None;
    }
    let d = [
        mu[0] - cam.center.x,
        mu[1] - cam.center.y,
        mu[2] - cam.center.z,
    ];
    let len = dot3(d, d).sqrt();
    let mut basis = [0.0; 36];
    sh_basis(degree, d[0] / len, d[1] / len, d[2] / len, &mut basis);
    let k1 = num_coeffs(degree) - 1;
    let col: [f64; 3] = std::array::from_fn(|ch| {
        let mut acc = basis[0] * q[11 + ch];
        for k in 0..k1 {
            acc += basis[k + 1] * q[14 + k * 3 + ch];
        }
        (acc + 0.5).max(0.0)
    });
    Some(Splat64 {
        m: [fx * x / z + cam.cx, fy * y / z + cam.cy],
        con: [c / det, -b / det, a / det],
        o,
        c: col,
        z,
    })
}

/// Raw parameters flattened per Gaussian: mean 3, log-scale 3, quat 4, logit 1, dc 3, rest.
pub fn flatten(g: &Gaussians) -> Vec<f64> {
    let mut p = Vec::new();
    for i in 0..g.len() {
        p.extend(g.means[i].iter().map(|&v| v as f64));
        p.extend(g.log_scales[i].iter().map(|&v| v as f64));
        p.extend(g.quats[i].iter().map(|&v| v as f64));
        p.push(g.opacity_logits[i] as f64);
        p.extend(g.sh_dc[i].iter().map(|&v| v as f64));
        p.extend(g.rest(i).iter().map(|&v| v as f64));
    }
    p
}

/// A smooth scene: a few large Gaussians that cover the whole small image with
/// 1/255 < α < 0.99 at every pixel and T well above 1e-4, so the loss is differentiable.
pub fn smooth_scene(degree: u32, seed: u64) -> Gaussians {
    let mut u = Uniform::new(seed);
    let mut g = Gaussians::new(degree).unwrap();
    let k1 = num_coeffs(degree) - 1;
    for _ in 0..5 {
        let mean = [u.range(-0.3, 0.3), u.range(-0.2, 0.2), u.range(2.5, 4.0)];
        let ls = [
            u.range(0.4f32.ln(), 0.9f32.ln()),
            u.range(0.4f32.ln(), 0.9f32.ln()),
            u.range(0.3f32.ln(), 0.6f32.ln()),
        ];
        let q = [
            u.range(0.5, 1.0),
            u.range(-0.5, 0.5),
            u.range(-0.5, 0.5),
            u.range(-0.5, 0.5),
        ];
        let op = u.range(-1.0, 0.5);
        let dc = [u.range(-0.8, 0.8), u.range(-0.8, 0.8), u.range(-0.8, 0.8)];
        let rest: Vec<f32> = (0..k1 * 3).map(|_| u.range(-0.2, 0.2)).collect();
        g.push(mean, ls, q, op, dc, &rest);
    }
    g
}

/// The float type the untiled blend accumulates in: f32 is the rasterizer's arithmetic,
/// f64 the knob "f64 accumulation" (α still in f32).
pub trait Accum:
    Copy
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
{
    fn of(v: f32) -> Self;
}
impl Accum for f32 {
    fn of(v: f32) -> Self {
        v
    }
}
impl Accum for f64 {
    fn of(v: f32) -> Self {
        f64::from(v)
    }
}

/// The blend of SPEC.md §5.4 with no tiles: per pixel over every visible splat of `p` in
/// the total order (camera z bits, index), σ and α in f32 exactly as the rasterizer's
/// (`exp` the crate's own), transmittance and sums in `A`. With `A = f32` it is the
/// rasterizer's arithmetic with the tile lists replaced by one list for the whole image
/// (the rasterizer must give the same bits: the tile size changes no output but
/// `n_contrib`); with `A = f64` it is the knob "f64 accumulation". Default cut-offs.
/// Returns rgb (interleaved), alpha, D, ED, final T.
pub fn blend_untiled<A: Accum>(
    p: &unseen::raster::project::Projected,
    width: usize,
    height: usize,
    bg: [f32; 3],
) -> [Vec<A>; 5] {
    use unseen::math::fastexp::exp;
    use unseen::raster::composite::{
        EXPECTED_DEPTH_EPS, MAX_ALPHA, SIGMA_CLAMP, TRANSMITTANCE_STOP,
    };
    use unseen::raster::project::ALPHA_THRESHOLD;
    let mut order: Vec<usize> = (0..p.radii.len())
        .filter(|&i| p.radii[i][0] > 0 || p.radii[i][1] > 0)
        .collect();
    order.sort_by_key(|&i| (p.splats[i].depth.to_bits(), i));
    let splats: Vec<_> = order.iter().map(|&i| p.splats[i]).collect();
    let npix = width * height;
    let zero = A::of(0.0);
    let mut out = [
        vec![zero; npix * 3],
        vec![zero; npix],
        vec![zero; npix],
        vec![zero; npix],
        vec![zero; npix],
    ];
    for pi in 0..npix {
        let (px, py) = ((pi % width) as f32 + 0.5, (pi / width) as f32 + 0.5);
        let (mut t, mut c, mut d) = (A::of(1.0), [zero; 3], zero);
        for s in &splats {
            let (dx, dy) = (s.mean[0] - px, s.mean[1] - py);
            let sigma = 0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) + s.conic[1] * dx * dy;
            let e = exp(-(if sigma < SIGMA_CLAMP {
                sigma
            } else {
                SIGMA_CLAMP
            }));
            let a = s.opacity * e;
            let alpha = if a < MAX_ALPHA { a } else { MAX_ALPHA };
            if !(sigma >= 0.0 && alpha >= ALPHA_THRESHOLD) {
                continue;
            }
            let a = A::of(alpha);
            let nt = t * (A::of(1.0) - a);
            if nt <= A::of(TRANSMITTANCE_STOP) {
                break;
            }
            let w = a * t;
            for (ck, &sk) in c.iter_mut().zip(&s.color) {
                *ck = *ck + A::of(sk) * w;
            }
            d = d + A::of(s.depth) * w;
            t = nt;
        }
        for k in 0..3 {
            out[0][pi * 3 + k] = c[k] + t * A::of(bg[k]);
        }
        let alpha = A::of(1.0) - t;
        out[1][pi] = alpha;
        out[2][pi] = d;
        let eps = A::of(EXPECTED_DEPTH_EPS);
        out[3][pi] = d / if alpha > eps { alpha } else { eps };
        out[4][pi] = t;
    }
    out
}

/// A loss `Σ_p w_rgb·rgb + w_alpha·alpha + w_depth·D` of the f64 twin (default cut-offs)
/// whose change under new parameters of one Gaussian is found by re-walking only the pixels
/// that Gaussian reaches before or after the change: central differences of every
/// parameter of a scene of thousands of Gaussians at the cost of their footprints. Each
/// walk also records the pixel's decisions (which splats it blends, which at the 0.99
/// clamp, whether it stops), so a difference that crosses one — where the loss has a jump
/// or a kink and no derivative — can be told apart.
pub struct LocalLoss {
    degree: u32,
    cam: Camera,
    bg: [f64; 3],
    stride: usize,
    /// Per Gaussian: its splat (None: drawn nowhere) and its rank in the (z, index) order.
    splats: Vec<Option<Splat64>>,
    /// Per pixel: the Gaussians whose α passes the threshold there, in blend order.
    lists: Vec<Vec<u32>>,
    /// Per Gaussian: the pixels whose list holds it.
    reach: Vec<Vec<u32>>,
    /// Per pixel: the loss term and the decisions' signature.
    base: Vec<(f64, u64)>,
    w_rgb: Vec<f64>,
    w_alpha: Vec<f64>,
    w_depth: Vec<f64>,
}

/// The loss's change and whether every decision stayed the same.
pub struct Change {
    pub delta: f64,
    pub same_decisions: bool,
}

impl LocalLoss {
    pub fn new(
        g: &Gaussians,
        p: &[f64],
        cam: &Camera,
        bg: [f64; 3],
        w_rgb: &[f32],
        w_alpha: &[f32],
        w_depth: &[f32],
    ) -> LocalLoss {
        let stride = 14 + 3 * g.rest_per_channel();
        let splats: Vec<Option<Splat64>> = (0..g.len())
            .map(|i| {
                project64(
                    &p[i * stride..(i + 1) * stride],
                    g.sh_degree,
                    cam,
                    1.0 / 255.0,
                )
            })
            .collect();
        let mut order: Vec<usize> = (0..g.len()).filter(|&i| splats[i].is_some()).collect();
        order.sort_by(|&a, &b| {
            let (za, zb) = (splats[a].unwrap().z, splats[b].unwrap().z);
            za.total_cmp(&zb).then(a.cmp(&b))
        });
        let npix = (cam.width * cam.height) as usize;
        let mut lists = vec![Vec::new(); npix];
        let mut reach = vec![Vec::new(); g.len()];
        for (pi, list) in lists.iter_mut().enumerate() {
            let (px, py) = Self::centre(cam, pi);
            for &i in &order {
                if splats[i].unwrap().alpha_at(px, py, 1.0 / 255.0).is_some() {
                    list.push(i as u32);
                    reach[i].push(pi as u32);
                }
            }
        }
        let mut me = LocalLoss {
            degree: g.sh_degree,
            cam: cam.clone(),
            bg,
            stride,
            splats,
            lists,
            reach,
            base: Vec::new(),
            w_rgb: w_rgb.iter().map(|&v| f64::from(v)).collect(),
            w_alpha: w_alpha.iter().map(|&v| f64::from(v)).collect(),
            w_depth: w_depth.iter().map(|&v| f64::from(v)).collect(),
        };
        me.base = (0..npix).map(|pi| me.walk(pi, usize::MAX, None)).collect();
        me
    }

    fn centre(cam: &Camera, pi: usize) -> (f64, f64) {
        let w = cam.width as usize;
        ((pi % w) as f64 + 0.5, (pi / w) as f64 + 0.5)
    }

    /// Pixel `pi`'s loss term and decisions with Gaussian `i`'s splat replaced by `new`.
    fn walk(&self, pi: usize, i: usize, new: Option<&Splat64>) -> (f64, u64) {
        let (px, py) = Self::centre(&self.cam, pi);
        let new_alpha = new.and_then(|s| s.alpha_at(px, py, 1.0 / 255.0));
        let mut pending = new_alpha.map(|a| (new.unwrap(), a));
        let (mut tt, mut col, mut dd) = (1.0f64, [0.0; 3], 0.0);
        let mut sig: u64 = 0xcbf2_9ce4_8422_2325;
        let mut mix = |v: u64| sig = (sig ^ v).wrapping_mul(0x100_0000_01b3);
        let mut stopped = false;
        let mut blend =
            |s: &Splat64, alpha: f64, id: usize, tt: &mut f64, mix: &mut dyn FnMut(u64)| {
                let nt = *tt * (1.0 - alpha);
                if nt <= 1e-4 {
                    return false;
                }
                for (c, sc) in col.iter_mut().zip(s.c) {
                    *c += sc * alpha * *tt;
                }
                dd += s.z * alpha * *tt;
                *tt = nt;
                mix(id as u64 * 2 + u64::from(alpha >= 0.99));
                true
            };
        for &j in &self.lists[pi] {
            let j = j as usize;
            if j == i {
                continue;
            }
            let sj = self.splats[j].as_ref().unwrap();
            if let Some((sn, an)) = pending.filter(|(sn, _)| (sn.z, i) < (sj.z, j)) {
                pending = None;
                if !blend(sn, an, i, &mut tt, &mut mix) {
                    stopped = true;
                    break;
                }
            }
            let alpha = sj.alpha_at(px, py, 1.0 / 255.0).unwrap();
            if !blend(sj, alpha, j, &mut tt, &mut mix) {
                stopped = true;
                break;
            }
        }
        if let Some((sn, an)) = pending.filter(|_| !stopped) {
            stopped = !blend(sn, an, i, &mut tt, &mut mix);
        }
        mix(u64::from(stopped));
        let mut loss = (1.0 - tt) * self.w_alpha[pi] + dd * self.w_depth[pi];
        for (k, c) in col.iter().enumerate() {
            loss += (c + tt * self.bg[k]) * self.w_rgb[pi * 3 + k];
        }
        (loss, sig)
    }

    /// The change of the loss when Gaussian `i` takes the parameters `q` (its flattened
    /// row), over the pixels it reaches before or after.
    pub fn change(&self, i: usize, q: &[f64]) -> Change {
        let new = project64(q, self.degree, &self.cam, 1.0 / 255.0);
        let npix = self.base.len();
        let mut touched = vec![false; npix];
        for &pi in &self.reach[i] {
            touched[pi as usize] = true;
        }
        if let Some(s) = &new {
            for (pi, t) in touched.iter_mut().enumerate() {
                let (px, py) = Self::centre(&self.cam, pi);
                *t |= s.alpha_at(px, py, 1.0 / 255.0).is_some();
            }
        }
        let (mut delta, mut same) = (0.0, true);
        for pi in (0..npix).filter(|&pi| touched[pi]) {
            let (loss, sig) = self.walk(pi, i, new.as_ref());
            delta += loss - self.base[pi].0;
            same &= sig == self.base[pi].1;
        }
        Change {
            delta,
            same_decisions: same,
        }
    }

    /// Values per Gaussian in a flattened row.
    pub fn stride(&self) -> usize {
        self.stride
    }
}
