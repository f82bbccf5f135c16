//! Gilbert–Johnson–Keerthi distance between convex shapes given by support maps, in f64
//! (SPEC.md §16). Written from van den Bergen (JGT 1999) and Ericson's closest-point
//! routines; no code from elsewhere.
//!
//! Iteration: `v` is the point of the current simplex (a subset of the Minkowski difference
//! `A − B`) closest to the origin; `w = s_A(−v) − s_B(v)` is the difference's support point in
//! direction `−v`. The loop stops when
//! - the simplex is a tetrahedron containing the origin, or `|v|` is at rounding level
//!   (`|v| ≤ ABS_EPS · scale`): **intersecting**;
//! - the duality gap `|v|² − v·w ≤ REL_EPS · |v|²` (van den Bergen's relative test), or `w`
//!   is already in the simplex, or `|v|` stopped decreasing: the distance is in
//!   `[lower, |v|]`, `lower` the largest support-plane distance `v·w/|v|` seen;
//! - after [`MAX_ITERATIONS`]: an error, never a silent answer.
//!
//! A lower bound at or below `touch_eps = TOUCH_REL · scale` (`scale` = the largest vertex
//! magnitude of either shape, at least 1e-300) counts as touching, i.e. colliding: two
//! views are independent only when certainly separated (on nearly parallel faces GJK can
//! stall with `|v|` well above the distance, SPEC.md §16.1).

use crate::error::{Error, Result};
use glam::DVec3;

/// Iteration limit: 16-vertex polyhedra converge in well under 20 iterations.
pub const MAX_ITERATIONS: usize = 128;
/// Relative duality-gap tolerance (van den Bergen's ε², here on the gap itself).
pub const REL_EPS: f64 = 1e-12;
/// `|v|` below `ABS_EPS · scale` is rounding noise: the origin is on the difference.
pub const ABS_EPS: f64 = 1e-14;
/// Distances up to `TOUCH_REL · scale` count as touching (colliding).
pub const TOUCH_REL: f64 = 1e-9;
/// A simplex tetrahedron with `|det| ≤ FLAT_REL · |e1|·|e2|·|e3|` is treated as flat.
pub const FLAT_REL: f64 = 1e-10;

/// A convex shape through its support map: the point of the shape farthest along `d`.
pub trait Support {
    fn support(&self, d: DVec3) -> DVec3;
    /// Largest coordinate magnitude (for the scale of the tolerances).
    fn scale(&self) -> f64;
}

/// The convex hull of a point set (ties in the support map go to the lowest index).
#[derive(Clone, Debug, PartialEq)]
pub struct ConvexHull {
    pub vertices: Vec<DVec3>,
}

impl ConvexHull {
    /// A hull of finite points; at least one.
    pub fn new(vertices: Vec<DVec3>) -> Result<Self> {
        if vertices.is_empty() {
            return Err(Error::invalid("a convex hull needs at least one vertex"));
        }
        if let Some(p) = vertices.iter().find(|p| !p.is_finite()) {
            return Err(Error::invalid(format!("vertex {p} is not finite")));
        }
        Ok(ConvexHull { vertices })
    }
}

impl Support for ConvexHull {
    fn support(&self, d: DVec3) -> DVec3 {
        let mut best = self.vertices[0];
        let mut best_dot = best.dot(d);
        for &p in &self.vertices[1..] {
            let t = p.dot(d);
            if t > best_dot {
                best = p;
                best_dot = t;
            }
        }
        best
    }
    fn scale(&self) -> f64 {
        self.vertices
            .iter()
            .map(|p| p.abs().max_element())
            .fold(0.0, f64::max)
    }
}

/// The answer of a query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Proximity {
    /// Distance between the shapes (0 when the simplex holds the origin): `|v|`, the length
    /// of a point of the Minkowski difference, so never below the true distance (up to
    /// rounding).
    pub distance: f64,
    /// A lower bound of the distance, exact up to rounding: the largest `v·w / |v|` of the
    /// iterations (the support plane's distance), at most `distance`; 0 when `distance`
    /// is (the origin in a tetrahedron, or `|v| ≤ ABS_EPS·scale`, which may hide a true
    /// distance up to that). `distance − lower_bound` is the duality gap left when the
    /// query stopped: rounding level except where GJK stalls on nearly parallel faces
    /// (SPEC.md §16.1).
    pub lower_bound: f64,
    /// True when they may overlap or touch within `touch_eps`: `lower_bound ≤ touch_eps`
    /// (a stalled query errs towards colliding).
    pub intersect: bool,
    /// The touching tolerance used (`TOUCH_REL · scale`).
    pub touch_eps: f64,
    pub iterations: usize,
}

/// Up to 4 points of the Minkowski difference (no heap allocation).
#[derive(Clone, Copy)]
struct Simplex {
    p: [DVec3; 4],
    n: usize,
}

impl Simplex {
    fn contains(&self, w: DVec3) -> bool {
        self.p[..self.n].contains(&w)
    }
    fn push(&mut self, w: DVec3) {
        self.p[self.n] = w;
        self.n += 1;
    }
    /// Keep the points whose bit is set in `mask`, in order.
    fn keep(&mut self, mask: u8) {
        let mut k = 0;
        for i in 0..self.n {
            if mask & (1 << i) != 0 {
                self.p[k] = self.p[i];
                k += 1;
            }
        }
        self.n = k;
    }
}

/// The stopping rules of [`proximity_with`]; [`Default`] is the constants above, what
/// [`proximity`] uses (their cost in accuracy and time: `cargo bench --bench accuracy`,
/// SPEC.md §5.10).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerances {
    pub max_iterations: usize,
    pub rel_eps: f64,
    pub abs_eps: f64,
    pub touch_rel: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            max_iterations: MAX_ITERATIONS,
            rel_eps: REL_EPS,
            abs_eps: ABS_EPS,
            touch_rel: TOUCH_REL,
        }
    }
}

/// Distance and intersection of two convex shapes.
pub fn proximity(a: &dyn Support, b: &dyn Support) -> Result<Proximity> {
    proximity_with(a, b, &Tolerances::default())
}

/// [`proximity`] with other stopping rules.
pub fn proximity_with(a: &dyn Support, b: &dyn Support, tol: &Tolerances) -> Result<Proximity> {
    let scale = a.scale().max(b.scale()).max(1e-300);
    let touch_eps = tol.touch_rel * scale;
    let abs_eps = tol.abs_eps * scale;
    let sup = |d: DVec3| a.support(-d) - b.support(d);
    let mut simplex = Simplex {
        p: [DVec3::ZERO; 4],
        n: 0,
    };
    // Start from the difference of two vertices along an arbitrary axis.
    let mut v = a.support(DVec3::X) - b.support(-DVec3::X);
    let done = |distance: f64, lower: f64, iterations: usize| {
        debug_assert!(
            lower <= distance + 1e-13 * scale,
            "support-plane bound {lower} above the distance {distance}"
        );
        let lower_bound = lower.min(distance);
        Proximity {
            distance,
            lower_bound,
            intersect: lower_bound <= touch_eps,
            touch_eps,
            iterations,
        }
    };
    let mut lower = 0f64;
    for it in 1..=tol.max_iterations {
        let vv = v.length_squared();
        if vv.sqrt() <= abs_eps {
            return Ok(done(0.0, 0.0, it));
        }
        let w = sup(v);
        lower = lower.max(v.dot(w) / vv.sqrt());
        if vv - v.dot(w) <= tol.rel_eps * vv || simplex.contains(w) {
            return Ok(done(vv.sqrt(), lower, it));
        }
        simplex.push(w);
        let (closest, inside) = closest_on_simplex(&mut simplex);
        if inside {
            return Ok(done(0.0, 0.0, it));
        }
        if it > 1 && closest.length_squared() >= vv {
            // No progress that `|v|²` can show (the first `v` was only a direction, not a
            // simplex point). Usually `v` is then as close as rounding allows; on nearly
            // parallel faces a better simplex exists but gains less than an ulp, and the
            // gap to `lower` stays above rounding (SPEC.md §16.1).
            return Ok(done(vv.sqrt(), lower, it));
        }
        v = closest;
    }
    Err(Error::invalid(format!(
        "GJK did not converge in {} iterations (distance estimate {})",
        tol.max_iterations,
        v.length()
    )))
}

/// Reduce `s` (1–4 points) to the smallest subset whose hull holds the point closest to the
/// origin; return that point and whether the origin is inside a full tetrahedron.
fn closest_on_simplex(s: &mut Simplex) -> (DVec3, bool) {
    let p = s.p;
    match s.n {
        1 => (p[0], false),
        2 => {
            let (q, keep) = closest_segment(p[0], p[1]);
            s.keep(keep);
            (q, false)
        }
        3 => {
            let (q, keep) = closest_triangle(p[0], p[1], p[2]);
            s.keep(keep);
            (q, false)
        }
        _ => closest_tetrahedron(s),
    }
}

/// Closest point to the origin on segment `ab` and the vertex mask of its feature.
fn closest_segment(a: DVec3, b: DVec3) -> (DVec3, u8) {
    let ab = b - a;
    let den = ab.length_squared();
    if den == 0.0 {
        return (a, 0b01);
    }
    let t = -a.dot(ab) / den;
    if t <= 0.0 {
        (a, 0b01)
    } else if t >= 1.0 {
        (b, 0b10)
    } else {
        (a + ab * t, 0b11)
    }
}

/// Closest point to the origin on triangle `abc` (Ericson, "Real-Time Collision
/// Detection" §5.1.5, Voronoi regions) and the vertex mask of its feature; a degenerate
/// triangle falls back to its edges.
fn closest_triangle(a: DVec3, b: DVec3, c: DVec3) -> (DVec3, u8) {
    let (ab, ac, ap) = (b - a, c - a, -a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, 0b001);
    }
    let bp = -b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, 0b010);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let t = d1 / (d1 - d3);
        return (a + ab * t, 0b011);
    }
    let cp = -c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, 0b100);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let t = d2 / (d2 - d6);
        return (a + ac * t, 0b101);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * t, 0b110);
    }
    let den = va + vb + vc;
    if den > 0.0 && den.is_finite() {
        let (v, w) = (vb / den, vc / den);
        return (a + ab * v + ac * w, 0b111);
    }
    // Degenerate (collinear) triangle: the best of its edges.
    let mut best = closest_segment(a, b);
    for (p, q, shift) in [(b, c, 1), (a, c, 2)] {
        let (pt, keep) = closest_segment(p, q);
        if pt.length_squared() < best.0.length_squared() {
            // Map the segment's (first, second) bits onto the triangle's vertices.
            let first = if shift == 1 { 0b010 } else { 0b001 };
            let mut m = 0;
            if keep & 1 != 0 {
                m |= first;
            }
            if keep & 2 != 0 {
                m |= 0b100;
            }
            best = (pt, m);
        }
    }
    best
}

/// Tetrahedron: the origin inside (every face sees it on the inner side) is an
/// intersection; otherwise the closest of the faces it lies outside of (all faces when the
/// tetrahedron is flat).
fn closest_tetrahedron(s: &mut Simplex) -> (DVec3, bool) {
    let p = s.p;
    let faces = [[0, 1, 2, 3], [0, 1, 3, 2], [0, 2, 3, 1], [1, 2, 3, 0]];
    // A tetrahedron whose volume is at rounding level relative to its edges is flat: its
    // face-side signs mean nothing, so every face is searched and "inside" is never claimed.
    let (e1, e2, e3) = (p[1] - p[0], p[2] - p[0], p[3] - p[0]);
    let flat = e1.dot(e2.cross(e3)).abs() <= FLAT_REL * e1.length() * e2.length() * e3.length();
    let mut best: Option<(DVec3, u8)> = None;
    for f in faces {
        let (a, b, c, d) = (p[f[0]], p[f[1]], p[f[2]], p[f[3]]);
        let n = (b - a).cross(c - a);
        let outside = flat || n.dot(-a) * n.dot(d - a) < 0.0;
        if !outside {
            continue;
        }
        let (q, keep) = closest_triangle(a, b, c);
        if best.is_none_or(|bq| q.length_squared() < bq.0.length_squared()) {
            let mut m = 0u8;
            for (k, &vi) in f[..3].iter().enumerate() {
                if keep & (1 << k) != 0 {
                    m |= 1 << vi;
                }
            }
            best = Some((q, m));
        }
    }
    match best {
        Some((q, keep)) => {
            s.keep(keep);
            (q, false)
        }
        None => (DVec3::ZERO, true),
    }
}
