//! Independent camera views (paper §3.3.1, SPEC.md §16.2): the collision graph of the
//! candidate views' inpainted-region frustums, a maximal independent set chosen greedily
//! in the caller's order, and a closed nearest-neighbour trajectory through it.

use super::frustum::{Outline, Polyhedron, region_frustum};
use super::gjk::{ConvexHull, proximity};
use crate::camera::Camera;
use crate::error::{Error, Result};
use glam::DVec3;

/// The result of the selection, all indices into the candidate list.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Selection {
    /// Colliding pairs `(i, j)`, `i < j`, in lexicographic order.
    pub edges: Vec<(usize, usize)>,
    /// The independent views, in the greedy order.
    pub independent: Vec<usize>,
    /// The independent views in trajectory order (starts at `independent[0]`; the tour
    /// closes back to it).
    pub trajectory: Vec<usize>,
    /// Consecutive trajectory neighbours (including the closing pair): the gaps the
    /// dependent views fill.
    pub gaps: Vec<(usize, usize)>,
}

/// The collision graph: `edges[i]` lists the candidates whose frustum collides with `i`'s
/// (touching counts, §16.1).
pub fn collision_graph(frustums: &[ConvexHull]) -> Result<Vec<(usize, usize)>> {
    let mut edges = Vec::new();
    for i in 0..frustums.len() {
        for j in i + 1..frustums.len() {
            let p = proximity(&frustums[i], &frustums[j])
                .map_err(|e| Error::invalid(format!("views {i} and {j}: {}", e.message)))?;
            if p.intersect {
                edges.push((i, j));
            }
        }
    }
    Ok(edges)
}

/// Select independent views. `order` is the greedy order (default: `0..n`); `centers` are
/// the camera centres for the trajectory.
pub fn select(
    frustums: &[ConvexHull],
    centers: &[DVec3],
    order: Option<&[usize]>,
) -> Result<Selection> {
    check_order(frustums.len(), centers, order)?;
    let edges = collision_graph(frustums)?;
    select_in_graph(frustums.len(), edges, centers, order)
}

/// [`select`] on a given collision graph of `n` views (pairs `i < j`): what a port's
/// selection is compared with when a pair's verdict lies within noise of contact.
pub fn select_in_graph(
    n: usize,
    edges: Vec<(usize, usize)>,
    centers: &[DVec3],
    order: Option<&[usize]>,
) -> Result<Selection> {
    check_order(n, centers, order)?;
    let default: Vec<usize> = (0..n).collect();
    let order = order.unwrap_or(&default);
    let mut adj = vec![Vec::new(); n];
    for &(i, j) in &edges {
        if i >= j || j >= n {
            return Err(Error::invalid(format!(
                "no edge ({i}, {j}) among {n} views (pairs i < j)"
            )));
        }
        if adj[i].contains(&j) {
            return Err(Error::invalid(format!(
                "the edge ({i}, {j}) is listed twice"
            )));
        }
        adj[i].push(j);
        adj[j].push(i);
    }
    let mut chosen = vec![false; n];
    let mut independent = Vec::new();
    for &i in order {
        if !adj[i].iter().any(|&j| chosen[j]) {
            chosen[i] = true;
            independent.push(i);
        }
    }
    let (trajectory, gaps) = closed_tour(&independent, centers);
    Ok(Selection {
        edges,
        independent,
        trajectory,
        gaps,
    })
}

fn check_order(n: usize, centers: &[DVec3], order: Option<&[usize]>) -> Result<()> {
    if centers.len() != n {
        return Err(Error::invalid(format!(
            "{n} frustums but {} camera centres",
            centers.len()
        )));
    }
    let mut seen = vec![false; n];
    for &i in order.unwrap_or(&[]) {
        if i >= n || std::mem::replace(&mut seen[i], true) {
            return Err(Error::invalid(format!(
                "the order lists view {i} twice or out of range"
            )));
        }
    }
    Ok(())
}

/// The most views the exact set searches ([`maximal_independent_sets`], [`colliding_sets`])
/// take: they visit all `2ⁿ` subsets (a million at 20).
pub const EXACT_MAX_VIEWS: usize = 20;

/// Per view, the bitmask of the views it collides with (`n` ≤ [`EXACT_MAX_VIEWS`]).
fn neighbour_masks(n: usize, edges: &[(usize, usize)]) -> Result<Vec<u32>> {
    if n > EXACT_MAX_VIEWS {
        return Err(Error::invalid(format!(
            "an exact set search over {n} views (at most {EXACT_MAX_VIEWS}: it visits every subset)"
        )));
    }
    let mut adj = vec![0u32; n];
    for &(i, j) in edges {
        if i >= n || j >= n || i == j {
            return Err(Error::invalid(format!(
                "no edge ({i}, {j}) among {n} views"
            )));
        }
        adj[i] |= 1 << j;
        adj[j] |= 1 << i;
    }
    Ok(adj)
}

/// The views of a bitmask, ascending.
pub fn members(mask: u32) -> Vec<usize> {
    (0..32).filter(|&i| mask & (1 << i) != 0).collect()
}

/// Every maximal independent set of the graph of `n` views (no two collide and no view can
/// be added), as bitmasks in increasing order; `n` ≤ [`EXACT_MAX_VIEWS`].
pub fn maximal_independent_sets(n: usize, edges: &[(usize, usize)]) -> Result<Vec<u32>> {
    let adj = neighbour_masks(n, edges)?;
    let all = (1u32 << n) - 1;
    let mut out = Vec::new();
    for set in 1..=all {
        let independent = members(set).iter().all(|&i| adj[i] & set == 0);
        let maximal = || (0..n).all(|i| set & (1 << i) != 0 || adj[i] & set != 0);
        if independent && maximal() {
            out.push(set);
        }
    }
    Ok(out)
}

/// Every set of `k` of the `n` views in which at least one pair collides, as bitmasks in
/// increasing order; `n` ≤ [`EXACT_MAX_VIEWS`].
pub fn colliding_sets(n: usize, edges: &[(usize, usize)], k: usize) -> Result<Vec<u32>> {
    let adj = neighbour_masks(n, edges)?;
    let all = (1u32 << n) - 1;
    Ok((1..=all)
        .filter(|s| s.count_ones() as usize == k && members(*s).iter().any(|&i| adj[i] & s != 0))
        .collect())
}

/// The closed nearest-neighbour tour through `views` (indices into `centers`), starting at
/// `views[0]`, ties to the lower index, and its gaps: consecutive pairs including the
/// closing one (none for fewer than 2 views).
pub fn closed_tour(views: &[usize], centers: &[DVec3]) -> (Vec<usize>, Vec<(usize, usize)>) {
    let mut trajectory = Vec::with_capacity(views.len());
    let mut left: Vec<usize> = views.to_vec();
    left.sort_unstable();
    if let Some(&start) = views.first() {
        left.retain(|&v| v != start);
        trajectory.push(start);
        let mut cur = start;
        while !left.is_empty() {
            let (k, _) = left
                .iter()
                .enumerate()
                .map(|(k, &v)| (k, (centers[v] - centers[cur]).length_squared()))
                .fold((0, f64::INFINITY), |b, x| if x.1 < b.1 { x } else { b });
            cur = left.remove(k);
            trajectory.push(cur);
        }
    }
    let m = trajectory.len();
    let gaps = if m < 2 {
        Vec::new()
    } else {
        (0..m)
            .map(|k| (trajectory[k], trajectory[(k + 1) % m]))
            .collect()
    };
    (trajectory, gaps)
}

/// Paper §3.2 steps 3–4 from the candidates' inpainting masks and depth ranges: the
/// frustum of each region (`outline`), the collision graph, the independent set (greedy in
/// `order`, default the given order) and the closed tour over the camera centres.
pub fn select_regions(
    cams: &[&Camera],
    masks: &[Vec<bool>],
    ranges: &[[f64; 2]],
    outline: Outline,
    order: Option<&[usize]>,
) -> Result<(Vec<Polyhedron>, Selection)> {
    if masks.len() != cams.len() || ranges.len() != cams.len() {
        return Err(Error::invalid(format!(
            "{} cameras, {} masks and {} depth ranges",
            cams.len(),
            masks.len(),
            ranges.len()
        )));
    }
    let polys: Vec<Polyhedron> = cams
        .iter()
        .zip(masks)
        .zip(ranges)
        .map(|((c, m), &r)| {
            region_frustum(c, m, r, outline)
                .map_err(|e| Error::invalid(format!("view '{}': {}", c.name, e.message)))
        })
        .collect::<Result<_>>()?;
    let hulls: Vec<ConvexHull> = polys.iter().map(|p| p.hull()).collect::<Result<_>>()?;
    let centers: Vec<DVec3> = cams.iter().map(|c| c.center).collect();
    let sel = select(&hulls, &centers, order)?;
    Ok((polys, sel))
}
