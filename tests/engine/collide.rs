//! GJK against an independent exact oracle: the separating-axis test for two frustums
//! (5 + 5 face normals — near/far share one — and the cross products of their 6 + 6 edge
//! directions), on seeded random pairs and hand-made degenerate cases.

use super::polytope::{Frustum, exact_distance, random_frustum, sat_gap};
use glam::{DMat3, DVec3};
use unseen::collide::gjk::{ConvexHull, Proximity, TOUCH_REL, proximity};
use unseen::rng::Uniform;

fn query(a: &Frustum, b: &Frustum) -> Proximity {
    proximity(&a.hull(), &b.hull()).expect("GJK converges")
}

/// ≥ 100 000 seeded random pairs: GJK and SAT agree on intersect/separated except within
/// the touching band, and GJK's distance is never below SAT's gap (SAT's best axis gap is
/// a lower bound of the distance).
#[test]
fn gjk_agrees_with_separating_axes_on_random_frustum_pairs() {
    let mut u = Uniform::new(2024);
    let (mut agree, mut sep, mut inter, mut band) = (0, 0, 0, 0);
    for _ in 0..100_000 {
        let a = random_frustum(&mut u, DVec3::ZERO);
        let far = (a.v[4] - a.v[0]).length().max(1e-3);
        let off = DVec3::new(
            u.range(-1.0, 1.0) as f64,
            u.range(-1.0, 1.0) as f64,
            u.range(-1.0, 1.0) as f64,
        ) * far
            * 0.8;
        let b = random_frustum(&mut u, off);
        let p = query(&a, &b);
        let gap = sat_gap(&a, &b);
        let scale =
            a.v.iter()
                .chain(&b.v)
                .map(|v| v.abs().max_element())
                .fold(0.0, f64::max);
        // The band: both answers are within 100 touching tolerances of contact.
        if gap.abs() <= 100.0 * TOUCH_REL * scale {
            band += 1;
            continue;
        }
        if gap > 0.0 {
            assert!(
                !p.intersect,
                "SAT separates by {gap}, GJK says intersect ({p:?})\nA {:?}\nB {:?}",
                a.v, b.v
            );
            assert!(
                p.distance >= gap * (1.0 - 1e-9),
                "distance {} < SAT gap {gap}",
                p.distance
            );
            sep += 1;
        } else {
            assert!(
                p.intersect,
                "SAT overlaps by {}, GJK says distance {}",
                -gap, p.distance
            );
            inter += 1;
        }
        agree += 1;
    }
    assert!(
        sep > 10_000 && inter > 10_000,
        "both outcomes exercised: {sep} / {inter}"
    );
    eprintln!("separated {sep}, intersecting {inter}, touching band {band}");
    assert!(band < 100, "{band} pairs in the touching band");
    assert_eq!(agree + band, 100_000);
}

/// GJK against the exact distance (`polytope::exact_distance`, by exhaustion over feature
/// pairs) on seeded pairs of three families (`polytope::Family`): 20 000 random, 6 000
/// facing (nearly parallel faces) and 6 000 facing closer and flatter. On every pair the
/// exact distance lies in GJK's interval `[lower_bound, distance]` (± `GJK_EXACT_REL` of
/// the scale) and a pair the separating-axis test finds overlapping by more than 100
/// touching tolerances is colliding; outside that band a pair is separated exactly when
/// its lower bound clears the touching tolerance. Random pairs: the distance is exact
/// (within `GJK_EXACT_REL`) and the verdict equals the exact one. Facing pairs: GJK can
/// stall (SPEC.md §16.1), and the stall errs only towards "colliding". Every interval is
/// narrower than `GJK_STALL_REL` of the scale.
#[test]
fn gjk_distance_is_exact_on_random_and_facing_frustum_pairs() {
    use super::polytope::{Family, draw_pair, pair_scale};
    /// A few ulps of the scale: the vertices and the exhaustive distances are rounded at
    /// that level (measured: 6.0e-16 on the random pairs).
    const GJK_EXACT_REL: f64 = 1e-14;
    /// The widest interval a stall left, with margin: measured 1.1e-6 (an overlapping
    /// close facing pair reported at distance 2.8e-8 with lower bound 0, so colliding).
    const GJK_STALL_REL: f64 = 1e-5;
    let mut u = Uniform::new(77);
    // Each family with its count and the most pairs it may leave in the touching band (the
    // close facing pairs are drawn down to 1e-10 of the face apart, inside the band).
    let families = [
        (Family::Random, 20_000, 200),
        (Family::Facing, 6_000, 600),
        (Family::FacingClose, 6_000, 3_000),
    ];
    for (family, count, max_band) in families {
        let (mut band, mut widest, mut conservative) = (0usize, 0f64, 0usize);
        for k in 0..count {
            let (a, b) = draw_pair(&mut u, family, k);
            let scale = pair_scale(&a, &b);
            let p = query(&a, &b);
            let sat = sat_gap(&a, &b);
            let tol = 100.0 * TOUCH_REL * scale;
            if sat < -tol {
                assert!(p.intersect, "{family:?} {k}: overlap {} called {p:?}", -sat);
            }
            if sat.abs() <= tol {
                band += 1;
                continue;
            }
            let exact = exact_distance(&a, &b);
            let slack = GJK_EXACT_REL * scale;
            assert!(
                p.lower_bound - slack <= exact && exact <= p.distance + slack,
                "{family:?} {k}: exact {exact} outside [{}, {}]",
                p.lower_bound,
                p.distance
            );
            let width = (p.distance - p.lower_bound) / scale;
            widest = widest.max(width);
            let separated = exact > p.touch_eps;
            assert!(
                width <= GJK_STALL_REL,
                "{family:?} {k}: {p:?}, exact {exact}"
            );
            if family == Family::Random {
                assert!(
                    (p.distance - exact).abs() <= slack,
                    "{k}: {p:?}, exact {exact}"
                );
                assert_eq!(p.intersect, !separated, "{k}: {p:?}, exact {exact}");
            } else {
                assert!(p.intersect || separated, "{family:?} {k}: {p:?}");
                conservative += usize::from(p.intersect && separated);
            }
        }
        eprintln!(
            "{family:?}: {count} pairs, {band} in the touching band, widest interval {widest:e} of the scale, {conservative} separated pairs called colliding"
        );
        assert!(band <= max_band, "{family:?}: {band} pairs in the band");
        // SPEC.md §16.1 states none in these draws.
        assert_eq!(
            conservative, 0,
            "{family:?}: separated pairs called colliding"
        );
    }
}

/// Hand-made cases at the edges.
#[test]
fn gjk_degenerate_and_touching_cases() {
    let id = DMat3::IDENTITY;
    let f = Frustum::new(DVec3::ZERO, id, 0.5, 0.4, 1.0, 10.0);
    // Identical.
    assert!(query(&f, &f).intersect);
    // One inside the other.
    let inner = Frustum::new(DVec3::new(0.0, 0.0, 2.0), id, 0.1, 0.1, 1.0, 3.0);
    assert!(query(&f, &inner).intersect);
    assert!(query(&inner, &f).intersect);
    // Sharing a face: a frustum of the same shape continuing beyond the far plane (same
    // apex, near = 10): the two touch along the far face.
    let next = Frustum::new(DVec3::ZERO, id, 0.5, 0.4, 10.0, 20.0);
    let p = query(&f, &next);
    assert!(p.intersect && p.distance <= p.touch_eps, "{p:?}");
    // Touching at a vertex: a box corner placed exactly on a far corner.
    let corner = f.v[6];
    let tiny = ConvexHull::new(vec![corner, corner + DVec3::ONE, corner + DVec3::X]).unwrap();
    assert!(proximity(&f.hull(), &tiny).unwrap().intersect);
    // Touching along an edge: a segment through a near edge, outside otherwise.
    let e0 = f.v[0] - DVec3::new(0.0, 0.0, 0.0);
    let seg = ConvexHull::new(vec![
        e0 + DVec3::new(-1.0, 0.0, 0.0),
        f.v[1] + DVec3::new(1.0, 0.0, 0.0),
    ])
    .unwrap();
    assert!(proximity(&f.hull(), &seg).unwrap().intersect);
    // Just apart: shifted past the far plane by 1e-6.
    let apart = Frustum::new(DVec3::new(0.0, 0.0, 1e-6), id, 0.5, 0.4, 10.0, 20.0);
    let p = query(&f, &apart);
    assert!(!p.intersect && (p.distance - 1e-6).abs() < 1e-12, "{p:?}");
    // Zero thickness (near = far): a rectangle.
    let flat = Frustum::new(DVec3::new(0.0, 0.0, 0.0), id, 0.5, 0.4, 5.0, 5.0);
    assert!(query(&f, &flat).intersect);
    let flat_far = Frustum::new(DVec3::new(0.0, 0.0, 20.0), id, 0.5, 0.4, 5.0, 5.0);
    let p = query(&f, &flat_far);
    assert!(!p.intersect && (p.distance - 15.0).abs() < 1e-9, "{p:?}");
    // Nearly parallel faces: a second frustum rotated by 1e-9 rad beside the first.
    let side = Frustum::new(
        DVec3::new(12.0, 0.0, 0.0),
        DMat3::from_rotation_y(1e-9),
        0.5,
        0.4,
        1.0,
        10.0,
    );
    let p = query(&f, &side);
    assert_eq!(p.intersect, sat_gap(&f, &side) <= 0.0, "{p:?}");
    // Scales 1e6 and 1e-6: the same configuration scaled gives the same answer.
    for s in [1e6, 1e-6] {
        let a = Frustum::new(DVec3::ZERO, id, 0.5, 0.4, s, 10.0 * s);
        let b = Frustum::new(
            DVec3::new(0.0, 0.0, 0.5 * s),
            id,
            0.5,
            0.4,
            10.0 * s,
            20.0 * s,
        );
        let p = query(&a, &b);
        assert!(
            !p.intersect && ((p.distance / s) - 0.5).abs() < 1e-9,
            "scale {s}: {p:?}"
        );
        let c = Frustum::new(
            DVec3::new(0.0, 0.0, -0.5 * s),
            id,
            0.5,
            0.4,
            10.0 * s,
            20.0 * s,
        );
        assert!(query(&a, &c).intersect, "scale {s}");
    }
    // Bad input is an error, not a panic.
    assert!(ConvexHull::new(vec![]).is_err());
    assert!(ConvexHull::new(vec![DVec3::new(f64::NAN, 0.0, 0.0)]).is_err());
}

/// 40 cameras on a ring looking outwards with random yaw: the greedy set is conflict-free
/// and maximal against the collision graph (checked pair by pair with GJK), deterministic,
/// and the trajectory visits every chosen view once, starting at the first, and closes.
#[test]
fn independent_views_are_maximal_conflict_free_and_toured() {
    use unseen::collide::independent::select;
    let mut u = Uniform::new(11);
    let (mut hulls, mut centers) = (Vec::new(), Vec::new());
    for k in 0..40 {
        let a = k as f64 / 40.0 * std::f64::consts::TAU + u.range(-0.2, 0.2) as f64;
        let c = DVec3::new(3.0 * a.cos(), 0.0, 3.0 * a.sin());
        // Looking outwards: camera z along the ring's normal, y down.
        let z = DVec3::new(a.cos(), 0.0, a.sin());
        let y = DVec3::NEG_Y;
        let rot = DMat3::from_cols(y.cross(z), y, z);
        let f = Frustum::new(c, rot, 0.4, 0.3, 2.0, u.range(3.0, 8.0) as f64);
        hulls.push(f.hull());
        centers.push(c);
    }
    let s = select(&hulls, &centers, None).unwrap();
    assert_eq!(s, select(&hulls, &centers, None).unwrap(), "deterministic");
    let collide = |i: usize, j: usize| proximity(&hulls[i], &hulls[j]).unwrap().intersect;
    for (a, &i) in s.independent.iter().enumerate() {
        for &j in &s.independent[a + 1..] {
            assert!(!collide(i, j), "chosen {i} and {j} collide");
        }
    }
    for v in 0..40 {
        if !s.independent.contains(&v) {
            assert!(
                s.independent.iter().any(|&i| collide(i, v)),
                "{v} could be added"
            );
        }
    }
    for &(i, j) in &s.edges {
        assert!(i < j && collide(i, j));
    }
    assert!(
        s.independent.len() > 2 && s.independent.len() < 40,
        "{:?}",
        s.independent
    );
    let mut tour = s.trajectory.clone();
    assert_eq!(tour[0], s.independent[0]);
    tour.sort_unstable();
    let mut chosen = s.independent.clone();
    chosen.sort_unstable();
    assert_eq!(tour, chosen, "each chosen view once");
    assert_eq!(s.gaps.len(), s.trajectory.len());
    assert_eq!(s.gaps.last().unwrap().1, s.trajectory[0], "closed");
    // A custom order changes the greedy pick; bad orders are errors.
    let rev: Vec<usize> = (0..40).rev().collect();
    let r = select(&hulls, &centers, Some(&rev)).unwrap();
    assert_eq!(r.independent[0], 39);
    assert!(select(&hulls, &centers, Some(&[0, 0])).is_err());
    assert!(select(&hulls, &centers[..3], None).is_err());
}

mod frustums {
    use crate::support::reference;
    use glam::DVec3;
    use unseen::camera::inria::read_cameras_json;
    use unseen::collide::frustum::{
        Outline, Polyhedron, depth_range, mean_range, obj_text, region_frustum,
    };
    use unseen::io::image::read_exr;

    /// Outward Newell normals: the largest signed distance of `p` outside any face plane
    /// (≤ 0 inside), relative to the polyhedron's size.
    fn outside(poly: &Polyhedron, p: DVec3) -> f64 {
        let scale = poly
            .vertices
            .iter()
            .map(|v| v.abs().max_element())
            .fold(0.0, f64::max);
        poly.faces
            .iter()
            .map(|f| {
                let mut n = DVec3::ZERO;
                for k in 0..f.len() {
                    let (a, b) = (poly.vertices[f[k]], poly.vertices[f[(k + 1) % f.len()]]);
                    n += a.cross(b);
                }
                n.normalize().dot(p - poly.vertices[f[0]]) / scale
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// A blob mask on a real view: every masked pixel's 3D point (Mitsuba depth) lies in
    /// the frustum built from the mask and the masked depth range, for both outlines; the
    /// hull frustum lies inside the bounding-box one; corners reproject exactly.
    #[test]
    fn region_frustum_encloses_the_masked_geometry() {
        let root = reference("scenes/lounge");
        let cams = read_cameras_json(&root.join("cameras.json")).unwrap();
        let cam = &cams[5];
        let depth = read_exr(&root.join(format!("depth/{}.exr", cam.name)), &["Y"])
            .unwrap()
            .data;
        let (w, h) = (cam.width as usize, cam.height as usize);
        // An L-shaped region plus a diagonal stroke: the hull is much tighter than the box.
        let mask: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                ((20..50).contains(&x) && (30..100).contains(&y))
                    || ((20..120).contains(&x) && (80..100).contains(&y))
                    || ((x - y - 10).abs() < 3 && (60..110).contains(&x))
            })
            .collect();
        let range = depth_range(&depth, &mask).unwrap();
        assert!(range[0] > 0.0 && range[0] < range[1]);
        let bbox = region_frustum(cam, &mask, range, Outline::BoundingBox).unwrap();
        let hull = region_frustum(cam, &mask, range, Outline::Hull).unwrap();
        assert_eq!(bbox.vertices.len(), 8);
        assert_eq!(bbox.faces.len(), 6);
        assert!(hull.vertices.len() > 8);
        for (i, &m) in mask.iter().enumerate() {
            if !m {
                continue;
            }
            let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let z = depth[i] as f64;
            let d = DVec3::new((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0);
            let p = cam.center + cam.world_from_camera_rotation * (d * z);
            assert!(
                outside(&bbox, p) < 1e-12,
                "pixel {i} outside the box frustum"
            );
            assert!(
                outside(&hull, p) < 1e-12,
                "pixel {i} outside the hull frustum"
            );
        }
        for &v in &hull.vertices {
            assert!(
                outside(&bbox, v) < 1e-12,
                "hull vertex outside the box frustum"
            );
        }
        // Corners: (20, 30) at the near plane.
        let q = cam.camera_from_world_point(bbox.vertices[0]);
        let (u, v) = (cam.fx * q.x / q.z + cam.cx, cam.fy * q.y / q.z + cam.cy);
        assert!((q.z - range[0]).abs() < 1e-12 * range[0]);
        assert!(
            (u - 20.0).abs() < 1e-9 && (v - 30.0).abs() < 1e-9,
            "{u} {v}"
        );
        // Eq. 4 averages; bad input is a clear error.
        assert_eq!(mean_range(&[[1.0, 3.0], [2.0, 5.0]]).unwrap(), [1.5, 4.0]);
        assert_eq!(
            mean_range(&[[1.0, 3.0], [2.0, 5.0], [4.5, 4.0]]).unwrap(),
            [2.5, 4.0]
        );
        assert!(mean_range(&[]).is_err());
        let none = vec![false; w * h];
        let e = region_frustum(cam, &none, range, Outline::Hull).unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        let e = region_frustum(cam, &mask, [2.0, 1.0], Outline::Hull).unwrap_err();
        assert!(e.to_string().contains("near"), "{e}");
        assert!(region_frustum(cam, &mask[1..], range, Outline::Hull).is_err());
        assert!(depth_range(&depth, &none).is_err());
        // Zero thickness (near = far) is a valid, flat frustum.
        let flat = region_frustum(cam, &mask, [2.0, 2.0], Outline::BoundingBox).unwrap();
        assert_eq!(flat.vertices[..4], flat.vertices[4..]);
        let f = flat.hull().unwrap();
        assert!(unseen::collide::gjk::proximity(&f, &f).unwrap().intersect);
    }

    /// OBJ export reads back with tobj: the same faces with the same corners (tobj parses
    /// f32; our text is the f64 shortest round-trip form), one model per frustum.
    #[test]
    fn frustum_obj_reads_back_with_tobj() {
        let root = reference("scenes/gallery");
        let cams = read_cameras_json(&root.join("cameras.json")).unwrap();
        let polys: Vec<Polyhedron> = cams[..3]
            .iter()
            .map(|cam| {
                let n = (cam.width * cam.height) as usize;
                let mask: Vec<bool> = (0..n).map(|i| (i * 7919) % 97 < 3).collect();
                region_frustum(cam, &mask, [0.5, 4.0], Outline::Hull).unwrap()
            })
            .collect();
        let text = obj_text(&polys);
        let (models, _) =
            tobj::load_obj_buf(&mut text.as_bytes(), &tobj::LoadOptions::default(), |_| {
                Err(tobj::LoadError::OpenFileFailed)
            })
            .unwrap();
        assert_eq!(models.len(), 3);
        for (m, p) in models.iter().zip(&polys) {
            assert_eq!(m.name, p.name);
            // tobj renumbers vertices in order of first use: compare face by face.
            let pos = &m.mesh.positions;
            assert_eq!(m.mesh.face_arities.len(), p.faces.len());
            let mut at = 0;
            for (face, &arity) in p.faces.iter().zip(&m.mesh.face_arities) {
                assert_eq!(face.len(), arity as usize);
                for &vi in face {
                    let k = m.mesh.indices[at] as usize;
                    for c in 0..3 {
                        assert_eq!(pos[3 * k + c], p.vertices[vi][c] as f32);
                    }
                    at += 1;
                }
            }
        }
    }
}

/// Eq. 4 over `n` equal ranges is exactly the range, so a deterministic inpainting slot's
/// one inpainting stands for all `n` bit for bit (SPEC.md §20.2). The naive `Σ/n` misses for
/// a measured ~14 % of draws at `n = 3`, which the test checks it would catch.
#[test]
fn mean_of_equal_ranges_is_exact_so_one_deterministic_inpainting_stands_for_n() {
    use unseen::collide::frustum::mean_range;
    let mut u = unseen::rng::Uniform::new(35);
    let (mut naive_misses, draws) = (0usize, 20_000usize);
    for _ in 0..draws {
        // Depths over six decades, as scenes in metres and millimetres give.
        let near = 10f64.powf(-3.0 + 6.0 * u.unit_f64());
        let r = [near, near * (1.0 + 10.0 * u.unit_f64())];
        for n in 1..=8 {
            let rs = vec![r; n];
            assert_eq!(mean_range(&rs).unwrap(), r, "n = {n}, r = {r:?}");
        }
        let naive = (r[0] + r[0] + r[0]) / 3.0;
        naive_misses += usize::from(naive != r[0]);
    }
    let share = naive_misses as f64 / draws as f64;
    assert!(
        share > 0.05,
        "the naive mean missed only {share}: the test lost its teeth"
    );
}

/// The exact set searches of the selection rules (SPEC.md §16.2, §20.2) against sets
/// listed by hand, and against brute force on random graphs: every maximal independent
/// set and nothing else; every `k`-set with a colliding pair.
#[test]
fn exact_set_searches_list_every_maximal_independent_and_every_colliding_set() {
    use unseen::collide::independent::{colliding_sets, maximal_independent_sets, members};
    // The path 0 – 1 – 2 – 3.
    let path = [(0, 1), (1, 2), (2, 3)];
    let sets: Vec<Vec<usize>> = maximal_independent_sets(4, &path)
        .unwrap()
        .into_iter()
        .map(members)
        .collect();
    assert_eq!(sets, [vec![0, 2], vec![0, 3], vec![1, 3]]);
    let pairs: Vec<Vec<usize>> = colliding_sets(4, &path, 2)
        .unwrap()
        .into_iter()
        .map(members)
        .collect();
    assert_eq!(pairs, [vec![0, 1], vec![1, 2], vec![2, 3]]);
    assert!(colliding_sets(4, &[], 2).unwrap().is_empty());
    assert_eq!(maximal_independent_sets(3, &[]).unwrap(), [0b111]);
    let e = maximal_independent_sets(21, &[]).unwrap_err().to_string();
    assert!(e.contains("at most 20"), "{e}");
    // Random graphs of 7 views: brute force over all subsets.
    let mut u = Uniform::new(5);
    for _ in 0..50 {
        let n = 7;
        let mut edges = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                if u.unit_f64() < 0.4 {
                    edges.push((i, j));
                }
            }
        }
        let collides = |s: u32| {
            edges
                .iter()
                .any(|&(i, j)| s >> i & 1 == 1 && s >> j & 1 == 1)
        };
        let want: Vec<u32> = (1u32..1 << n)
            .filter(|&s| !collides(s) && (0..n).all(|i| s >> i & 1 == 1 || collides(s | 1 << i)))
            .collect();
        assert_eq!(maximal_independent_sets(n, &edges).unwrap(), want);
        for k in 1..=n {
            let want: Vec<u32> = (1u32..1 << n)
                .filter(|&s| s.count_ones() as usize == k && collides(s))
                .collect();
            assert_eq!(colliding_sets(n, &edges, k).unwrap(), want);
        }
    }
}
