//! Frustums of inpainted regions (paper §3.3.1 step 3, SPEC.md §16.3): the convex
//! polyhedron that bounds the 3D geometry an inpainting of a view can add, between the
//! planes `z = D_min` and `z = D_max` of the camera (z is camera depth, as everywhere).
//!
//! The image-plane outline is either the bounding rectangle of the mask's pixels
//! ([`Outline::BoundingBox`], the paper's "view frustum for only the inpainting region") or
//! the convex hull of the mask's pixels ([`Outline::Hull`], tighter, still convex). Pixel
//! `(j, i)` covers `[j, j+1) × [i, i+1)`, so outlines run along pixel edges; the hull is
//! computed on integer corners (exact). The polyhedron is the outline's cone cut by the two
//! planes: `2n` vertices for an `n`-gon outline.

use super::gjk::ConvexHull;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::math::hull::monotone_chain;
use glam::DVec3;
use std::fmt::Write as _;
use std::path::Path;

/// Image-plane outline of the region.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outline {
    BoundingBox,
    Hull,
}

crate::error::text_enum!(Outline, "outline", { BoundingBox => "bounding_box", Hull => "hull" });

/// A convex polyhedron with outward-oriented polygon faces (for export and inspection).
#[derive(Clone, Debug, PartialEq)]
pub struct Polyhedron {
    pub name: String,
    pub vertices: Vec<DVec3>,
    /// Vertex indices per face, counter-clockwise seen from outside.
    pub faces: Vec<Vec<usize>>,
}

impl Polyhedron {
    /// The vertex set as a GJK support map.
    pub fn hull(&self) -> Result<ConvexHull> {
        ConvexHull::new(self.vertices.clone())
    }
}

/// The `[min, max]` of the valid depths (finite, > 0) under the mask (`D^{i,j}` of paper
/// Eq. 4 for one inpainting). An error when the mask selects no valid depth.
pub fn depth_range(depth: &[f32], mask: &[bool]) -> Result<[f64; 2]> {
    if depth.len() != mask.len() {
        return Err(Error::invalid(format!(
            "{} depths but {} mask pixels",
            depth.len(),
            mask.len()
        )));
    }
    let mut r = [f64::INFINITY, f64::NEG_INFINITY];
    for (&d, _) in depth
        .iter()
        .zip(mask)
        .filter(|(d, m)| **m && d.is_finite() && **d > 0.0)
    {
        r = [r[0].min(d as f64), r[1].max(d as f64)];
    }
    if r[0] > r[1] {
        return Err(Error::invalid("the mask covers no valid depth"));
    }
    Ok(r)
}

/// Paper Eq. 4: the mean of the `n` inpaintings' ranges, as `r₀ + Σ(rⱼ − r₀)/n`: exactly
/// `r` when all `n` ranges are `r` (in f64 `(r + r + r)/3 ≠ r` for about one `r` in seven),
/// so the pipeline's single inpainting for a deterministic slot, whose `n` inpaintings are
/// equal, is bit for bit the mean of all `n` (SPEC.md §20.2).
pub fn mean_range(ranges: &[[f64; 2]]) -> Result<[f64; 2]> {
    let Some(&r0) = ranges.first() else {
        return Err(Error::invalid("no depth range to average"));
    };
    let n = ranges.len() as f64;
    let dev = ranges[1..].iter().fold([0.0, 0.0], |a, r| {
        [a[0] + (r[0] - r0[0]), a[1] + (r[1] - r0[1])]
    });
    Ok([r0[0] + dev[0] / n, r0[1] + dev[1] / n])
}

/// The image-plane outline of the mask's pixels, counter-clockwise in image coordinates
/// (x right, y down), on integer pixel corners; `None` for an empty mask.
pub fn mask_outline(mask: &[bool], width: usize, outline: Outline) -> Option<Vec<[i64; 2]>> {
    let height = mask.len() / width.max(1);
    let mut rows = Vec::new();
    for y in 0..height {
        let row = &mask[y * width..(y + 1) * width];
        if let (Some(a), Some(b)) = (row.iter().position(|&m| m), row.iter().rposition(|&m| m)) {
            rows.push((y as i64, a as i64, b as i64 + 1));
        }
    }
    if rows.is_empty() {
        return None;
    }
    match outline {
        Outline::BoundingBox => {
            let (y0, y1) = (rows[0].0, rows[rows.len() - 1].0 + 1);
            let x0 = rows.iter().map(|r| r.1).min().expect("non-empty");
            let x1 = rows.iter().map(|r| r.2).max().expect("non-empty");
            Some(vec![[x0, y0], [x0, y1], [x1, y1], [x1, y0]])
        }
        Outline::Hull => {
            let mut pts: Vec<[i64; 2]> = rows
                .iter()
                .flat_map(|&(y, a, b)| [[a, y], [a, y + 1], [b, y], [b, y + 1]])
                .collect();
            pts.sort_unstable();
            pts.dedup();
            Some(convex_hull_2d(&pts))
        }
    }
}

/// The hull of sorted, distinct integer points without collinear points, counter-clockwise
/// in a y-down frame (clockwise in y-up).
fn convex_hull_2d(pts: &[[i64; 2]]) -> Vec<[i64; 2]> {
    let mut h = monotone_chain(pts);
    // y-up counter-clockwise is y-down clockwise: reverse for the y-down convention.
    h.reverse();
    h
}

/// The frustum of `cam`'s region `mask` (row-major, the camera's size) between camera
/// depths `near ≤ far` (both finite and > 0).
pub fn region_frustum(
    cam: &Camera,
    mask: &[bool],
    range: [f64; 2],
    outline: Outline,
) -> Result<Polyhedron> {
    cam.validate()?;
    let (w, h) = (cam.width as usize, cam.height as usize);
    if mask.len() != w * h {
        return Err(Error::invalid(format!(
            "the mask has {} pixels but camera '{}' is {w}x{h}",
            mask.len(),
            cam.name
        )));
    }
    let [near, far] = range;
    if !(near > 0.0 && near.is_finite() && far.is_finite() && near <= far) {
        return Err(Error::invalid(format!(
            "camera '{}': depth range [{near}, {far}] must satisfy 0 < near ≤ far < ∞",
            cam.name
        )));
    }
    let poly = mask_outline(mask, w, outline)
        .ok_or_else(|| Error::invalid(format!("camera '{}': the mask is empty", cam.name)))?;
    let n = poly.len();
    let point = |c: [i64; 2], z: f64| {
        let d = DVec3::new(
            (c[0] as f64 - cam.cx) / cam.fx,
            (c[1] as f64 - cam.cy) / cam.fy,
            1.0,
        );
        cam.center + cam.world_from_camera_rotation * (d * z)
    };
    let mut vertices: Vec<DVec3> = poly.iter().map(|&c| point(c, near)).collect();
    vertices.extend(poly.iter().map(|&c| point(c, far)));
    // Faces: near (seen from the camera, i.e. from outside, the outline's order is
    // counter-clockwise in y-down image coordinates = clockwise as seen looking along +z,
    // so it is reversed), far, and one quad per outline edge.
    let mut faces = vec![(0..n).rev().collect::<Vec<_>>(), (n..2 * n).collect()];
    for k in 0..n {
        let k1 = (k + 1) % n;
        faces.push(vec![k, k1, n + k1, n + k]);
    }
    let mut p = Polyhedron {
        name: cam.name.clone(),
        vertices,
        faces,
    };
    orient_outward(&mut p);
    Ok(p)
}

/// Make every face counter-clockwise seen from outside (Newell normal against the
/// centroid), whatever the camera's handedness; degenerate faces are left as they are.
fn orient_outward(p: &mut Polyhedron) {
    let c = p.vertices.iter().copied().sum::<DVec3>() / p.vertices.len() as f64;
    for f in &mut p.faces {
        let mut nrm = DVec3::ZERO;
        let mut fc = DVec3::ZERO;
        for k in 0..f.len() {
            let (a, b) = (p.vertices[f[k]], p.vertices[f[(k + 1) % f.len()]]);
            nrm += DVec3::new(
                (a.y - b.y) * (a.z + b.z),
                (a.z - b.z) * (a.x + b.x),
                (a.x - b.x) * (a.y + b.y),
            );
            fc += a;
        }
        fc /= f.len() as f64;
        if nrm.dot(fc - c) < 0.0 {
            f.reverse();
        }
    }
}

/// Wavefront OBJ of several polyhedra, one object (`o name`) each, 1-based indices,
/// coordinates in Rust's shortest round-trip form (so they read back bit for bit).
pub fn obj_text(polys: &[Polyhedron]) -> String {
    let mut s = String::from("# unseen: frustums of inpainted regions (SPEC.md §16.3)\n");
    let mut base = 1;
    for p in polys {
        let _ = writeln!(s, "o {}", p.name.replace(char::is_whitespace, "_"));
        for v in &p.vertices {
            let _ = writeln!(s, "v {:?} {:?} {:?}", v.x, v.y, v.z);
        }
        for f in &p.faces {
            s.push('f');
            for &i in f {
                let _ = write!(s, " {}", i + base);
            }
            s.push('\n');
        }
        base += p.vertices.len();
    }
    s
}

/// Write [`obj_text`] atomically.
pub fn write_obj(path: &Path, polys: &[Polyhedron]) -> Result<()> {
    crate::io::write_text(path, &obj_text(polys))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_outline_of_a_triangle_mask_is_exact() {
        // A staircase triangle: row y covers x in 0..=y, 4 rows.
        let w = 6;
        let mut m = vec![false; w * 4];
        for y in 0..4 {
            for x in 0..=y {
                m[y * w + x] = true;
            }
        }
        let hull = mask_outline(&m, w, Outline::Hull).unwrap();
        assert_eq!(hull, vec![[0, 4], [4, 4], [4, 3], [1, 0], [0, 0]]);
        let bbox = mask_outline(&m, w, Outline::BoundingBox).unwrap();
        assert_eq!(bbox, vec![[0, 0], [0, 4], [4, 4], [4, 0]]);
        assert!(mask_outline(&[false; 12], 6, Outline::Hull).is_none());
    }
}
