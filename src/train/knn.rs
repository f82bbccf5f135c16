//! Mean squared distance to the 3 nearest neighbours, for INRIA's scale initialization
//! (`distCUDA2` of simple-knn): a k-d tree with median splits (ties by index), exact
//! search. Squared distances are f32 sums in x, y, z order, so the result is the same on
//! every platform; the work is split into fixed chunks of query points.

use rayon::prelude::*;

struct Tree<'a> {
    pts: &'a [[f32; 3]],
    /// Point indices, arranged so that each node's subtree is a contiguous range whose
    /// median element is the node.
    order: Vec<u32>,
}

fn d2(a: [f32; 3], b: [f32; 3]) -> f32 {
    let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    (x * x + y * y) + z * z
}

impl<'a> Tree<'a> {
    fn new(pts: &'a [[f32; 3]]) -> Self {
        let mut order: Vec<u32> = (0..pts.len() as u32).collect();
        Self::build(pts, &mut order, 0);
        Tree { pts, order }
    }

    fn build(pts: &[[f32; 3]], ids: &mut [u32], depth: usize) {
        if ids.len() <= 1 {
            return;
        }
        let axis = depth % 3;
        let mid = ids.len() / 2;
        ids.select_nth_unstable_by(mid, |&a, &b| {
            pts[a as usize][axis]
                .total_cmp(&pts[b as usize][axis])
                .then(a.cmp(&b))
        });
        let (lo, hi) = ids.split_at_mut(mid);
        Self::build(pts, lo, depth + 1);
        Self::build(pts, &mut hi[1..], depth + 1);
    }

    /// Insert `(d, id)` into the sorted best-3 list.
    fn offer(best: &mut [(f32, u32); 3], d: f32, id: u32) {
        if (d, id) >= best[2] {
            return;
        }
        best[2] = (d, id);
        if best[2] < best[1] {
            best.swap(1, 2);
            if best[1] < best[0] {
                best.swap(0, 1);
            }
        }
    }

    fn search(&self, lo: usize, hi: usize, depth: usize, q: usize, best: &mut [(f32, u32); 3]) {
        if lo >= hi {
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let id = self.order[mid];
        let p = self.pts[id as usize];
        let qp = self.pts[q];
        if id as usize != q {
            Self::offer(best, d2(p, qp), id);
        }
        let axis = depth % 3;
        let diff = qp[axis] - p[axis];
        let (near, far) = if diff < 0.0 {
            ((lo, mid), (mid + 1, hi))
        } else {
            ((mid + 1, hi), (lo, mid))
        };
        self.search(near.0, near.1, depth + 1, q, best);
        if diff * diff <= best[2].0 {
            self.search(far.0, far.1, depth + 1, q, best);
        }
    }
}

/// For each point, the mean of the squared distances to its (up to) 3 nearest other
/// points; `f32::INFINITY` entries are left out of the mean, a lone point gets 0.
pub fn mean_sq_dist_3nn(pts: &[[f32; 3]]) -> Vec<f32> {
    let tree = Tree::new(pts);
    let mut out = vec![0f32; pts.len()];
    out.par_chunks_mut(4096).enumerate().for_each(|(c, chunk)| {
        for (k, o) in chunk.iter_mut().enumerate() {
            let q = c * 4096 + k;
            let mut best = [(f32::INFINITY, u32::MAX); 3];
            tree.search(0, pts.len(), 0, q, &mut best);
            let found: Vec<f32> = best.iter().map(|b| b.0).filter(|d| d.is_finite()).collect();
            *o = if found.is_empty() {
                0.0
            } else {
                found.iter().sum::<f32>() / found.len() as f32
            };
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Uniform;

    #[test]
    fn matches_brute_force() {
        let mut u = Uniform::new(9);
        let mut pts: Vec<[f32; 3]> = (0..700)
            .map(|_| [u.range(-1.0, 1.0), u.range(-1.0, 1.0), u.range(-1.0, 1.0)])
            .collect();
        pts.push(pts[3]); // a duplicate
        let fast = mean_sq_dist_3nn(&pts);
        for (i, p) in pts.iter().enumerate() {
            let mut d: Vec<f32> = (0..pts.len())
                .filter(|&j| j != i)
                .map(|j| d2(*p, pts[j]))
                .collect();
            d.sort_by(f32::total_cmp);
            let want = (d[0] + d[1]) + d[2];
            assert_eq!(fast[i], want / 3.0, "point {i}");
        }
        assert_eq!(mean_sq_dist_3nn(&pts[..1]), vec![0.0]);
    }
}
