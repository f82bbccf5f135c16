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
    let k1 = g.rest_per_channel();
    let stride = 14 + 3 * k1;
    let r = cam.camera_from_world_rotation();
    let t = cam.camera_from_world_translation();
    let rcw = [
        [r.x_axis.x, r.y_axis.x, r.z_axis.x],
        [r.x_axis.y, r.y_axis.y, r.z_axis.y],
        [r.x_axis.z, r.y_axis.z, r.z_axis.z],
    ];
    let (w, h) = (cam.width as f64, cam.height as f64);
    struct S {
        m: [f64; 2],
        con: [f64; 3],
        o: f64,
        c: [f64; 3],
        z: f64,
    }
    let mut splats: Vec<(f64, usize, S)> = Vec::new();
    for i in 0..n {
        let q = &p[i * stride..(i + 1) * stride];
        let mu = [q[0], q[1], q[2]];
        let x = rcw[0][0] * mu[0] + rcw[0][1] * mu[1] + rcw[0][2] * mu[2] + t.x;
        let y = rcw[1][0] * mu[0] + rcw[1][1] * mu[1] + rcw[1][2] * mu[2] + t.y;
        let z = rcw[2][0] * mu[0] + rcw[2][1] * mu[1] + rcw[2][2] * mu[2] + t.z;
        // The near plane is the f32 constant (0.01f32 < 0.01).
        if z < f64::from(0.01f32) {
            continue;
        }
        let s = [q[3].exp(), q[4].exp(), q[5].exp()];
        let rot = rotation_f64([q[6], q[7], q[8], q[9]]);
        let mut sig = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                for k in 0..3 {
                    sig[a][b] += rot[a][k] * s[k] * rot[b][k] * s[k];
                }
            }
        }
        let mut sc = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        sc[a][b] += rcw[a][k] * sig[k][l] * rcw[b][l];
                    }
                }
            }
        }
        let (fx, fy) = (cam.fx, cam.fy);
        let (tfx, tfy) = (0.5 * w / fx, 0.5 * h / fy);
        let tx = z * (x / z).clamp(-(cam.cx / fx + 0.3 * tfx), (w - cam.cx) / fx + 0.3 * tfx);
        let ty = z * (y / z).clamp(-(cam.cy / fy + 0.3 * tfy), (h - cam.cy) / fy + 0.3 * tfy);
        let j = [
            [fx / z, 0.0, -fx * tx / (z * z)],
            [0.0, fy / z, -fy * ty / (z * z)],
        ];
        let mut cov = [[0.0; 2]; 2];
        for a in 0..2 {
            for b in 0..2 {
                for k in 0..3 {
                    for l in 0..3 {
                        cov[a][b] += j[a][k] * sc[k][l] * j[b][l];
                    }
                }
            }
        }
        let (a, b, c) = (cov[0][0] + 0.3, cov[0][1], cov[1][1] + 0.3);
        let det = a * c - b * b;
        let o = 1.0 / (1.0 + (-q[10]).exp());
        if det.is_nan() || det <= 0.0 || o < alpha_threshold {
            continue;
        }
        let d = [
            mu[0] - cam.center.x,
            mu[1] - cam.center.y,
            mu[2] - cam.center.z,
        ];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let mut basis = [0.0; 36];
        sh_basis(g.sh_degree, d[0] / len, d[1] / len, d[2] / len, &mut basis);
        let mut col = [0.0; 3];
        for ch in 0..3 {
            let mut acc = basis[0] * q[11 + ch];
            for k in 0..k1 {
                acc += basis[k + 1] * q[14 + k * 3 + ch];
            }
            col[ch] = (acc + 0.5).max(0.0);
        }
        let m = [fx * x / z + cam.cx, fy * y / z + cam.cy];
        splats.push((
            z,
            i,
            S {
                m,
                con: [c / det, -b / det, a / det],
                o,
                c: col,
                z,
            },
        ));
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
            let (dx, dy) = (s.m[0] - px, s.m[1] - py);
            let sigma = 0.5 * (s.con[0] * dx * dx + s.con[2] * dy * dy) + s.con[1] * dx * dy;
            let alpha = (s.o * (-sigma).exp()).min(0.99);
            if sigma < 0.0 || alpha < alpha_threshold {
                continue;
            }
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
