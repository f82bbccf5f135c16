//! Frustum polytopes and two exact, GJK-independent answers about a pair of them: the
//! separating-axis test (intersect or not, and a lower bound of the distance) and the
//! distance itself by exhaustion over feature pairs. Shared by `collide.rs` and
//! `benches/accuracy.rs` (its `gjk frustums` stage).

use glam::{DMat3, DVec3};
use unseen::collide::gjk::ConvexHull;
use unseen::rng::Uniform;

/// A frustum: 8 corners (near 0–3, far 4–7, same order) and its centre.
pub struct Frustum {
    pub v: [DVec3; 8],
}

impl Frustum {
    pub fn new(center: DVec3, rot: DMat3, tan_x: f64, tan_y: f64, near: f64, far: f64) -> Self {
        let c =
            |z: f64, sx: f64, sy: f64| center + rot * DVec3::new(sx * tan_x * z, sy * tan_y * z, z);
        let s = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        let mut v = [DVec3::ZERO; 8];
        for (k, (sx, sy)) in s.iter().enumerate() {
            v[k] = c(near, *sx, *sy);
            v[4 + k] = c(far, *sx, *sy);
        }
        Frustum { v }
    }
    pub fn hull(&self) -> ConvexHull {
        ConvexHull::new(self.v.to_vec()).unwrap()
    }
    /// Face normals (not normalized): near/far, and the four sides.
    pub fn normals(&self) -> Vec<DVec3> {
        let v = &self.v;
        let mut n = vec![(v[1] - v[0]).cross(v[3] - v[0])];
        for k in 0..4 {
            let (a, b) = (k, (k + 1) % 4);
            n.push((v[b] - v[a]).cross(v[4 + a] - v[a]));
        }
        n
    }
    pub fn edges(&self) -> Vec<DVec3> {
        let v = &self.v;
        let mut e = vec![v[1] - v[0], v[3] - v[0]];
        for k in 0..4 {
            e.push(v[4 + k] - v[k]);
        }
        e
    }
}

/// The SAT answer: the largest normalized gap over all axes (> 0: separated by at least
/// that much; ≤ 0: overlapping, the value being minus the smallest penetration).
pub fn sat_gap(a: &Frustum, b: &Frustum) -> f64 {
    let mut axes = a.normals();
    axes.extend(b.normals());
    for ea in a.edges() {
        for eb in b.edges() {
            axes.push(ea.cross(eb));
        }
    }
    let mut best = f64::NEG_INFINITY;
    for ax in axes {
        let len = ax.length();
        if len < 1e-12 * a.v[0].length().max(1.0) || !len.is_finite() {
            continue;
        }
        let n = ax / len;
        let proj = |f: &Frustum| {
            f.v.iter()
                .map(|p| p.dot(n))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    (lo.min(x), hi.max(x))
                })
        };
        let ((alo, ahi), (blo, bhi)) = (proj(a), proj(b));
        best = best.max((blo - ahi).max(alo - bhi));
    }
    best
}

pub fn random_rotation(u: &mut Uniform) -> DMat3 {
    let q = glam::DQuat::from_xyzw(
        u.normal() as f64,
        u.normal() as f64,
        u.normal() as f64,
        u.normal() as f64,
    )
    .normalize();
    DMat3::from_quat(q)
}

pub fn log_uniform(u: &mut Uniform, lo: f64, hi: f64) -> f64 {
    (lo.ln() + (hi.ln() - lo.ln()) * u.unit() as f64).exp()
}

pub fn random_frustum(u: &mut Uniform, center: DVec3) -> Frustum {
    let near = log_uniform(u, 1e-3, 1e2);
    let far = near * log_uniform(u, 1.0001, 1e3);
    let (fx, fy) = (u.range(0.2, 2.6) as f64, u.range(0.2, 2.6) as f64);
    Frustum::new(
        center,
        random_rotation(u),
        (fx / 2.0).tan(),
        (fy / 2.0).tan(),
        near,
        far,
    )
}

/// Triangles of the six faces (near 0–3, far 4–7, four sides), each quad split in two.
const TRIANGLES: [[usize; 3]; 12] = [
    [0, 1, 2],
    [0, 2, 3],
    [4, 5, 6],
    [4, 6, 7],
    [0, 1, 5],
    [0, 5, 4],
    [1, 2, 6],
    [1, 6, 5],
    [2, 3, 7],
    [2, 7, 6],
    [3, 0, 4],
    [3, 4, 7],
];

/// The twelve edges (near ring, far ring, four sides).
const EDGES: [[usize; 2]; 12] = [
    [0, 1],
    [1, 2],
    [2, 3],
    [3, 0],
    [4, 5],
    [5, 6],
    [6, 7],
    [7, 4],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

/// Distance from `p` to the segment `ab`.
fn point_segment(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).length()
}

/// Distance from `p` to the triangle `abc`: to its plane when the projection falls inside
/// (on the inner side of all three edges), else to the nearest edge.
fn point_triangle(p: DVec3, [a, b, c]: [DVec3; 3]) -> f64 {
    let n = (b - a).cross(c - a);
    let len2 = n.length_squared();
    if len2 > 0.0 {
        let q = p - n * ((p - a).dot(n) / len2);
        let inside = n.dot((b - a).cross(q - a)) >= 0.0
            && n.dot((c - b).cross(q - b)) >= 0.0
            && n.dot((a - c).cross(q - c)) >= 0.0;
        if inside {
            return (p - a).dot(n).abs() / len2.sqrt();
        }
    }
    point_segment(p, a, b)
        .min(point_segment(p, b, c))
        .min(point_segment(p, c, a))
}

/// Distance between the segments `p0p1` and `q0q1`: a convex quadratic over the parameter
/// square, so its minimum is the lines' closest pair when that lies inside both segments,
/// else on the square's boundary (an end point against the other segment).
fn segment_segment(p0: DVec3, p1: DVec3, q0: DVec3, q1: DVec3) -> f64 {
    let ends = point_segment(p0, q0, q1)
        .min(point_segment(p1, q0, q1))
        .min(point_segment(q0, p0, p1))
        .min(point_segment(q1, p0, p1));
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, b) = (d1.length_squared(), d2.length_squared(), d1.dot(d2));
    let (c, f) = (d1.dot(r), d2.dot(r));
    let denom = a * e - b * b;
    // Parallel (or degenerate) segments: the end points attain the minimum. Otherwise any
    // `(s, t)` inside the square is a real pair of points, however ill-conditioned.
    if denom <= 0.0 {
        return ends;
    }
    let s = (b * f - c * e) / denom;
    let t = (a * f - b * c) / denom;
    if (0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t) {
        ends.min(((p0 + d1 * s) - (q0 + d2 * t)).length())
    } else {
        ends
    }
}

/// The exact distance of two frustums (0 when the separating-axis test finds no gap): the
/// smallest distance over vertex–triangle pairs both ways and edge–edge pairs, one of
/// which holds the closest points of two disjoint convex polytopes. Every candidate is a
/// distance between points of the two solids, so none is below the true distance.
pub fn exact_distance(a: &Frustum, b: &Frustum) -> f64 {
    if sat_gap(a, b) <= 0.0 {
        return 0.0;
    }
    let mut d = f64::INFINITY;
    for (p, q) in [(a, b), (b, a)] {
        for &v in &p.v {
            for t in TRIANGLES {
                d = d.min(point_triangle(v, t.map(|k| q.v[k])));
            }
        }
    }
    for [i, j] in EDGES {
        for [k, l] in EDGES {
            d = d.min(segment_segment(a.v[i], a.v[j], b.v[k], b.v[l]));
        }
    }
    d
}

/// A pair with nearly parallel facing faces: `a` is a random frustum (`random_frustum`),
/// `b` its mirror image across a plane parallel to one of `a`'s faces (`face`: 0 near,
/// 1 far, 2–5 sides) half of `gap` × the face's diagonal beyond it — so the mirrored face
/// is `gap` × the diagonal away —, turned by `angle` about a random axis in that plane
/// through the point above the face's centre. At `angle = 0` the faces are parallel.
pub fn facing_pair(u: &mut Uniform, face: usize, gap: f64, angle: f64) -> (Frustum, Frustum) {
    const FACES: [[usize; 4]; 6] = [
        [0, 1, 2, 3],
        [4, 5, 6, 7],
        [0, 1, 5, 4],
        [1, 2, 6, 5],
        [2, 3, 7, 6],
        [3, 0, 4, 7],
    ];
    let a = random_frustum(u, DVec3::ZERO);
    let f = FACES[face].map(|k| a.v[k]);
    let centre = (f[0] + f[1] + f[2] + f[3]) / 4.0;
    let inner = a.v.iter().copied().sum::<DVec3>() / 8.0;
    let mut n = (f[1] - f[0]).cross(f[3] - f[0]).normalize();
    if n.dot(centre - inner) < 0.0 {
        n = -n;
    }
    let pivot = centre + n * (0.5 * gap * (f[2] - f[0]).length());
    let axis = n.any_orthonormal_pair().0;
    let turn = DMat3::from_axis_angle(
        (axis * (u.range(-1.0, 1.0) as f64) + n.cross(axis) * (u.range(-1.0, 1.0) as f64))
            .try_normalize()
            .unwrap_or(axis),
        angle,
    );
    let mut b = Frustum { v: a.v };
    for p in &mut b.v {
        let mirrored = *p - n * (2.0 * (*p - pivot).dot(n));
        *p = pivot + turn * (mirrored - pivot);
    }
    (a, b)
}

/// The largest vertex coordinate magnitude of a pair (GJK's `scale`).
pub fn pair_scale(a: &Frustum, b: &Frustum) -> f64 {
    a.v.iter()
        .chain(&b.v)
        .map(|v| v.abs().max_element())
        .fold(0.0, f64::max)
}

/// A random pair: two `random_frustum`s, the second centred within ±1 of the first's
/// near-to-far length (so about half the pairs overlap).
pub fn random_pair(u: &mut Uniform) -> (Frustum, Frustum) {
    let a = random_frustum(u, DVec3::ZERO);
    let far = (a.v[4] - a.v[0]).length().max(1e-3);
    let off = DVec3::new(
        u.range(-1.0, 1.0) as f64,
        u.range(-1.0, 1.0) as f64,
        u.range(-1.0, 1.0) as f64,
    ) * far;
    let b = random_frustum(u, off);
    (a, b)
}

/// The families of pairs the GJK test and the accuracy bench draw: random pairs, facing
/// pairs with gaps 1e-6–1 of the face turned 1e-12–1e-2 rad, and facing pairs closer and
/// flatter (gaps 1e-10–1e-2, turned 1e-14–1e-4 rad), where GJK stalls most.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    Random,
    Facing,
    FacingClose,
}

/// Pair `k` of a family (the face cycles with `k`).
pub fn draw_pair(u: &mut Uniform, family: Family, k: usize) -> (Frustum, Frustum) {
    let (gaps, angles) = match family {
        Family::Random => return random_pair(u),
        Family::Facing => ((1e-6, 1.0), (1e-12, 1e-2)),
        Family::FacingClose => ((1e-10, 1e-2), (1e-14, 1e-4)),
    };
    let gap = log_uniform(u, gaps.0, gaps.1);
    let angle = log_uniform(u, angles.0, angles.1);
    facing_pair(u, k % 6, gap, angle)
}
