//! The convex hull of points in the plane (Andrew's monotone chain).

use std::ops::{Mul, Sub};

/// Andrew's monotone chain on points sorted lexicographically (x, then y) and distinct: the
/// convex hull without collinear points, counter-clockwise in a y-up frame (clockwise in a
/// y-down one), from the smallest point. Exact for integers; for floats, the orientation
/// test is the plain cross product. Collinear points give the segment's two ends, one point
/// gives nothing.
pub fn monotone_chain<T>(pts: &[[T; 2]]) -> Vec<[T; 2]>
where
    T: Copy + PartialOrd + Default + Sub<Output = T> + Mul<Output = T>,
{
    let cross = |o: [T; 2], a: [T; 2], b: [T; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut h: Vec<[T; 2]> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = h.len();
        let mut step = |p: [T; 2]| {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], p) <= T::default() {
                h.pop();
            }
            h.push(p);
        };
        if pass == 0 {
            pts.iter().for_each(|&p| step(p));
        } else {
            pts.iter().rev().for_each(|&p| step(p));
        }
        h.pop();
    }
    h
}

#[cfg(test)]
mod tests {
    use super::monotone_chain;

    /// A square with points inside and on its edges: the four corners, counter-clockwise
    /// (y up) from the smallest; the same in floats; collinear points: the two ends.
    #[test]
    fn hull_of_a_square_is_its_corners() {
        let mut pts: Vec<[i64; 2]> = Vec::new();
        for x in 0..=2 {
            for y in 0..=2 {
                pts.push([x, y]);
            }
        }
        assert_eq!(monotone_chain(&pts), vec![[0, 0], [2, 0], [2, 2], [0, 2]]);
        let f: Vec<[f64; 2]> = pts.iter().map(|p| [p[0] as f64, p[1] as f64]).collect();
        assert_eq!(
            monotone_chain(&f),
            vec![[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]
        );
        assert_eq!(
            monotone_chain(&[[0i64, 0], [1, 1], [2, 2]]),
            vec![[0, 0], [2, 2]]
        );
        assert!(monotone_chain(&[[3i64, 4]]).is_empty());
    }
}
