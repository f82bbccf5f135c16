//! GJK throughput on frustum pairs: `cargo bench --bench collide`.
//!
//! 100 000 seeded random frustum pairs (8 vertices each, poses, FOVs and near/far as in the
//! oracle test), one thread: queries per second and the mean iteration count.

use glam::{DMat3, DQuat, DVec3};
use std::time::Instant;
use unseen::collide::gjk::{ConvexHull, proximity};
use unseen::rng::Uniform;

fn frustum(u: &mut Uniform, center: DVec3) -> ConvexHull {
    let lu =
        |u: &mut Uniform, lo: f64, hi: f64| (lo.ln() + (hi.ln() - lo.ln()) * u.unit() as f64).exp();
    let near = lu(u, 1e-3, 1e2);
    let far = near * lu(u, 1.0001, 1e3);
    let (tx, ty) = (
        (u.range(0.2, 2.6) as f64 / 2.0).tan(),
        (u.range(0.2, 2.6) as f64 / 2.0).tan(),
    );
    let q = DQuat::from_xyzw(
        u.normal() as f64,
        u.normal() as f64,
        u.normal() as f64,
        u.normal() as f64,
    )
    .normalize();
    let r = DMat3::from_quat(q);
    let mut v = Vec::with_capacity(8);
    for z in [near, far] {
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            v.push(center + r * DVec3::new(sx * tx * z, sy * ty * z, z));
        }
    }
    ConvexHull::new(v).unwrap()
}

fn main() {
    let mut u = Uniform::new(7);
    let pairs: Vec<(ConvexHull, ConvexHull)> = (0..100_000)
        .map(|_| {
            let a = frustum(&mut u, DVec3::ZERO);
            let s = (a.vertices[4] - a.vertices[0]).length();
            let off = DVec3::new(
                u.range(-1.0, 1.0) as f64,
                u.range(-1.0, 1.0) as f64,
                u.range(-1.0, 1.0) as f64,
            ) * s;
            let b = frustum(&mut u, off);
            (a, b)
        })
        .collect();
    let mut best = f64::MAX;
    let (mut its, mut hits) = (0usize, 0usize);
    for _ in 0..5 {
        let t = Instant::now();
        its = 0;
        hits = 0;
        for (a, b) in &pairs {
            let p = proximity(a, b).unwrap();
            its += p.iterations;
            hits += p.intersect as usize;
        }
        best = best.min(t.elapsed().as_secs_f64());
    }
    println!(
        "GJK: {:.2} M queries/s on one thread ({} pairs, {:.1} % intersecting, {:.2} iterations on average)",
        pairs.len() as f64 / best * 1e-6,
        pairs.len(),
        100.0 * hits as f64 / pairs.len() as f64,
        its as f64 / pairs.len() as f64
    );
}
