//! Which candidates stage 1 generates (SPEC.md §20.2): the independent set by the
//! configured rule (the paper says "independent", not which maximal set) with the coverage
//! weight the rules compare, and the audit's colliding set matched to it on the coverage
//! the audit measures.

use crate::camera::Camera;
use crate::collide::independent::{colliding_sets, maximal_independent_sets, members};
use crate::error::Result;

/// Which independent set detection keeps (a choice the paper leaves open).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SelectionRule {
    /// Greedy in candidate order: a maximal set, not a maximum one (the default).
    #[default]
    Greedy,
    /// A maximum-cardinality independent set (ties: more coverage, then the first).
    MaxCardinality,
    /// The independent set of maximum [`Coverage`] (ties: more views, then the first).
    MaxCoverage,
}

crate::error::text_enum!(SelectionRule, "selection rule", {
    Greedy => "greedy",
    MaxCardinality => "max_cardinality",
    MaxCoverage => "max_coverage",
});

impl SelectionRule {
    pub fn is_default(&self) -> bool {
        *self == SelectionRule::Greedy
    }
}

/// The largest relative difference between the coverage of the audit's colliding set and
/// the independent set's ([`SurfaceCoverage`]) for the two to count as matched: 10 %.
pub const CONFLICT_COVERAGE_TOLERANCE: f64 = 0.10;

/// The least share of the sample of the unseen surface that two views of the audit's
/// colliding set must both generate for it to qualify: 5 %. Frustums that collide may
/// generate no common surface the evaluation views see (then no conflict can cost there);
/// independent sets overlap on 0–2 %.
pub const CONFLICT_MIN_OVERLAP: f64 = 0.05;

/// How the audit's colliding set is matched to the independent set (SPEC.md §20.2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConflictMatch {
    /// On [`SurfaceCoverage`]: the share of the evaluation views' unseen surface the set
    /// generates, the coverage the audit's diagnostics report. It reads the evaluation
    /// views and the truth: an audit control, never a method's choice.
    #[default]
    EvaluationCoverage,
}

crate::error::text_enum!(ConflictMatch, "conflict matching", {
    EvaluationCoverage => "evaluation_coverage",
});

/// The coverage of sets of candidate views that the audit measures (SPEC.md §21.5): of the
/// sample of the unseen surface
/// ([`visit_unseen_surface`](super::evaluate::visit_unseen_surface)), the share of points
/// some view of the set generated.
pub struct SurfaceCoverage {
    /// Per sample point some candidate generated, the candidates that did (bit `i`:
    /// candidate `i`).
    hits: Vec<u32>,
    /// Points in the sample (generated or not).
    points: u64,
}

impl SurfaceCoverage {
    /// From the sample's points, each given as the candidates that generated it; at most
    /// 32 candidates (detection's own limit).
    pub fn new(points: impl IntoIterator<Item = u32>) -> Self {
        let mut n = 0u64;
        let hits = points
            .into_iter()
            .inspect(|_| n += 1)
            .filter(|&b| b != 0)
            .collect();
        SurfaceCoverage { hits, points: n }
    }

    /// The share of the sample that `views` generated (0 for an empty sample).
    pub fn of(&self, views: &[usize]) -> f64 {
        self.share(views, 1)
    }

    /// The share of the sample that at least two of `views` generated: where their
    /// generations can conflict (the diagnostics' *overlap*).
    pub fn overlap(&self, views: &[usize]) -> f64 {
        self.share(views, 2)
    }

    fn share(&self, views: &[usize], at_least: u32) -> f64 {
        let set: u32 = views.iter().map(|&i| 1u32 << i).fold(0, |a, b| a | b);
        let n = self
            .hits
            .iter()
            .filter(|&&b| (b & set).count_ones() >= at_least)
            .count();
        n as f64 / self.points.max(1) as f64
    }
}

/// The coverage weight of sets of candidate views: the distinct voxels that their
/// inpainted regions' points occupy. A region's points are every `stride`-th pixel of its
/// mask unprojected with its aligned depth (the points stage 1 would add); the voxel edge
/// is the median over all points of the footprint of `stride` pixels at the point's depth
/// (`z·stride/f_x`), so a voxel holds about one point of one view, and two views that
/// generate the same surface share voxels.
pub struct Coverage {
    /// Per view, its voxels, sorted.
    voxels: Vec<Vec<[i64; 3]>>,
}

impl Coverage {
    pub fn new(cams: &[&Camera], masks: &[Vec<bool>], depths: &[Vec<f32>], stride: usize) -> Self {
        let stride = stride.max(1);
        let mut points: Vec<Vec<glam::DVec3>> = Vec::with_capacity(cams.len());
        let mut footprints = Vec::new();
        for ((cam, mask), depth) in cams.iter().zip(masks).zip(depths) {
            let (w, h) = (cam.width as usize, cam.height as usize);
            let mut pts = Vec::new();
            for y in (0..h).step_by(stride) {
                for x in (0..w).step_by(stride) {
                    let p = y * w + x;
                    let z = depth[p] as f64;
                    if mask[p] && z.is_finite() && z > 0.0 {
                        pts.push(cam.pixel_point(x, y, z));
                        footprints.push(z * stride as f64 / cam.fx);
                    }
                }
            }
            points.push(pts);
        }
        footprints.sort_by(f64::total_cmp);
        let edge = footprints.get(footprints.len() / 2).copied().unwrap_or(1.0);
        let voxels = points
            .iter()
            .map(|pts| {
                let mut v: Vec<[i64; 3]> = pts
                    .iter()
                    .map(|p| (*p / edge).floor().as_i64vec3().to_array())
                    .collect();
                v.sort_unstable();
                v.dedup();
                v
            })
            .collect();
        Coverage { voxels }
    }

    /// The coverage of `views`: the distinct voxels of their regions together.
    pub fn of(&self, views: &[usize]) -> usize {
        let mut all: Vec<[i64; 3]> = views
            .iter()
            .flat_map(|&i| self.voxels[i].iter().copied())
            .collect();
        all.sort_unstable();
        all.dedup();
        all.len()
    }
}

/// The independent set of the `n` candidates with collisions `edges` by `rule`
/// (ascending indices); `greedy` is the greedy set, which [`SelectionRule::Greedy`] keeps.
pub fn independent_set(
    rule: SelectionRule,
    n: usize,
    edges: &[(usize, usize)],
    greedy: &[usize],
    coverage: &Coverage,
) -> Result<Vec<usize>> {
    if rule == SelectionRule::Greedy {
        return Ok(greedy.to_vec());
    }
    let score = |set: &[usize]| match rule {
        SelectionRule::Greedy | SelectionRule::MaxCardinality => (set.len(), coverage.of(set)),
        SelectionRule::MaxCoverage => (coverage.of(set), set.len()),
    };
    let mut best: Option<((usize, usize), Vec<usize>)> = None;
    for set in maximal_independent_sets(n, edges)? {
        let v = members(set);
        let s = score(&v);
        if best.as_ref().is_none_or(|(b, _)| s > *b) {
            best = Some((s, v));
        }
    }
    Ok(best.map(|(_, v)| v).unwrap_or_default())
}

/// The audit's colliding set (SPEC.md §20.2): of the sets of `|independent|` candidates
/// in which some pair collides, those that *qualify* — [`SurfaceCoverage`] within
/// [`CONFLICT_COVERAGE_TOLERANCE`] of the independent set's, and generations overlapping
/// on at least [`CONFLICT_MIN_OVERLAP`] of the sample (else no conflict could cost) — and
/// of them the nearest in coverage (ties: the first); without one, the nearest in coverage
/// of all, not qualified. With its relative coverage difference (∞ when the independent
/// set covers nothing and it does) and whether it qualifies; `None` when no colliding set
/// exists (fewer than two views, or no collision).
pub fn conflicting_set(
    n: usize,
    edges: &[(usize, usize)],
    independent: &[usize],
    coverage: &SurfaceCoverage,
) -> Result<Option<(Vec<usize>, f64, bool)>> {
    let target = coverage.of(independent);
    // Qualified first, then the smaller coverage difference, then the first.
    let mut best: Option<((bool, f64), Vec<usize>)> = None;
    for set in colliding_sets(n, edges, independent.len())? {
        let v = members(set);
        let c = coverage.of(&v);
        let gap = if target > 0.0 {
            (c - target).abs() / target
        } else if c > 0.0 {
            f64::INFINITY
        } else {
            0.0
        };
        let qualifies =
            gap <= CONFLICT_COVERAGE_TOLERANCE && coverage.overlap(&v) >= CONFLICT_MIN_OVERLAP;
        let better = match &best {
            None => true,
            Some(((q, g), _)) => (qualifies && !q) || (qualifies == *q && gap < *g),
        };
        if better {
            best = Some(((qualifies, gap), v));
        }
    }
    Ok(best.map(|((q, g), v)| (v, g, q)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample of 100 points: `count` of them generated by exactly the views of `mask`, the
    /// rest by none.
    fn sample(parts: &[(u32, usize)]) -> SurfaceCoverage {
        let mut points = Vec::new();
        for &(mask, count) in parts {
            points.extend(std::iter::repeat_n(mask, count));
        }
        points.resize(100, 0);
        SurfaceCoverage::new(points)
    }

    /// The colliding set qualifies by coverage within 10 % *and* overlap of at least 5 %,
    /// then is the nearest in coverage; with none qualifying, the nearest of all, marked.
    #[test]
    fn the_colliding_set_qualifies_by_coverage_and_overlap_then_is_the_nearest() {
        // Views 0..4; independent {0, 1} covers 40 (20 + 20). Colliding pairs: (0, 2),
        // (1, 3), (2, 3). {0, 2}: view 0's 20 and view 2's 24, 6 shared → 38 (5 % off),
        // overlap 6 %. {1, 3}: 48 (20 % off). {2, 3}: 53.
        let s = sample(&[
            (0b0001, 14),
            (0b0101, 6),
            (0b0010, 19),
            (0b1010, 1),
            (0b0100, 18),
            (0b1000, 28),
        ]);
        let edges = [(0, 2), (1, 3), (2, 3)];
        assert_eq!(s.of(&[0, 1]), 0.40);
        assert_eq!(s.overlap(&[0, 2]), 0.06);
        let (v, gap, ok) = conflicting_set(4, &edges, &[0, 1], &s).unwrap().unwrap();
        assert_eq!((v, ok), (vec![0, 2], true));
        assert!((gap - 0.05).abs() < 1e-12, "{gap}");
        // Without the shared points nothing overlaps enough: the nearest, not qualified.
        let flat = sample(&[(0b0001, 20), (0b0010, 20), (0b0100, 18), (0b1000, 25)]);
        let (v, gap, ok) = conflicting_set(4, &edges, &[0, 1], &flat).unwrap().unwrap();
        assert_eq!((v, ok), (vec![0, 2], false));
        assert!((gap - 0.05).abs() < 1e-12, "{gap}");
        assert!(conflicting_set(4, &[], &[0, 1], &s).unwrap().is_none());
    }
}
