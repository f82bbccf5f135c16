"""Frustums of inpainted regions and independent views for ports: ``compare_frustum``'s and
``compare_views``' cases and known mistakes (SPEC.md §16.2, §16.3).

A region's frustum has no decision: its outline runs along integer pixel corners and its
depth range is a minimum and a maximum, so a port's vertices are judged as a set (any
order) within ``FRUSTUM_REL`` of the scale — loose enough for a float32 port, ten times
below the collision test's contact band. The independent set is greedy in candidate order,
exact given the collision graph; a pair within the collision test's contact band may be
decided either way, so every graph those pairs allow is tried and the port's set must be
one of their selections. The tour takes the nearest remaining camera centre; centres
within ``TOUR_REL`` of the nearest are ties either way.
"""

import itertools

import numpy as np

from ._collide import _rotation, frustum, viewmat
from ._stage import StageMistake, ellipse_mask

#: A port's frustum vertices may lie this share of the scale (the largest coordinate
#: magnitude) from the oracle's: float32 arithmetic (1e-7 relative, a few operations)
#: passes; every known mistake moves a vertex by ≥ 1e-3 of it.
FRUSTUM_REL = 1e-6
#: Squared centre distances within this share of the nearest one are ties in the tour.
TOUR_REL = 1e-6
#: The most near-contact pairs whose verdicts are enumerated (2^k graphs); a case with more
#: cannot judge the selection.


def _camera(rng, width, height):
    f = rng.uniform(0.6, 1.4) * width
    k = np.array([[f, 0, width / 2 + rng.uniform(-4, 4)],
                  [0, f * rng.uniform(0.9, 1.1), height / 2 + rng.uniform(-4, 4)],
                  [0, 0, 1]], np.float64)
    return k, viewmat(_rotation(rng), rng.uniform(-3, 3, size=3))


def frustum_case(seed):
    """A seeded case: a camera (``k``, ``viewmat``, ``width``, ``height``), a region
    ``mask`` (bool (H, W): 1–3 ellipses, at least 4 pixels), its ``depth`` (float32 (H, W),
    a tilted plane 0.5–6 m with noise, 5 % of the masked pixels invalid: 0, NaN or ∞) and
    the ``outline`` (bounding box and hull in turn)."""
    rng = np.random.default_rng(np.random.PCG64(40_000 + seed))
    w, h = int(rng.integers(40, 97)), int(rng.integers(30, 73))
    k, viewmat = _camera(rng, w, h)
    while True:
        mask = np.zeros((h, w), bool)
        for _ in range(rng.integers(1, 4)):
            mask |= ellipse_mask((h, w), rng, 1.5, 3)
        if mask.sum() >= 4:
            break
    yy, xx = np.mgrid[0:h, 0:w]
    depth = (rng.uniform(0.5, 3.0) + rng.uniform(-0.02, 0.02) * xx
             + rng.uniform(-0.02, 0.02) * yy + rng.normal(0, 0.05, (h, w)))
    depth = np.clip(depth, 0.5, 6.0).astype(np.float32)
    bad = mask & (rng.random((h, w)) < 0.05)
    depth[bad] = rng.choice(np.array([0.0, np.nan, np.inf], np.float32), size=int(bad.sum()))
    return {"k": k, "viewmat": viewmat, "width": w, "height": h, "mask": mask,
            "depth": depth, "outline": ("bounding_box", "hull")[seed % 2]}


FRUSTUM_MISTAKES = (
    StageMistake("pixel_centres", "the outline through pixel centres, not along pixel edges"),
    StageMistake("no_far_edge", "the bounding box's far edges at the last pixel's index "
                 "(its left/top edge), not one past it"),
    StageMistake("ray_distance", "near and far as distances along each ray, not camera z"),
    StageMistake("all_depths", "the depth range of the whole image, not of the region"),
    StageMistake("transposed", "the mask read transposed (x and y swapped)"),
    StageMistake("fy_from_fx", "the vertical focal length taken from the horizontal one "
                 "(fy = fx: square pixels assumed)"),
)


def _hull(points):
    """Andrew's monotone chain over integer or float 2D points (counter-clockwise)."""
    pts = sorted(set(map(tuple, points)))
    if len(pts) <= 2:
        return np.asarray(pts, np.float64)

    def half(seq):
        out = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return np.asarray(lower[:-1] + upper[:-1], np.float64)


def mistaken_frustum(name, case, dtype=np.float64):
    """The ``(V, 3)`` vertices mistake ``name`` computes (``"none"``: the conventions,
    without mistake), in ``dtype`` arithmetic."""
    mask, depth = case["mask"], case["depth"].astype(dtype)
    if name == "transposed":
        mask = mask.T.copy()
    ys, xs = np.nonzero(mask)
    if case["outline"] == "bounding_box" or name == "no_far_edge":
        x0, x1, y0, y1 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
        if name == "pixel_centres":
            x0, x1, y0, y1 = x0 + 0.5, x1 - 0.5, y0 + 0.5, y1 - 0.5
        if name == "no_far_edge":
            x1, y1 = x1 - 1, y1 - 1
        corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype)
    else:
        off = 0.5 if name == "pixel_centres" else 0.0
        if off:
            pts = np.stack([xs + off, ys + off], 1)
        else:
            pts = np.concatenate([np.stack([xs + dx, ys + dy], 1)
                                  for dx in (0, 1) for dy in (0, 1)])
        corners = _hull(pts).astype(dtype)
    valid = np.isfinite(depth) & (depth > 0)
    region = valid if name == "all_depths" else valid & case["mask"]
    near, far = depth[region].min(), depth[region].max()
    k, v = case["k"].astype(dtype), case["viewmat"].astype(dtype)
    if name == "fy_from_fx":
        k[1, 1] = k[0, 0]
    r_wc = v[:3, :3].T
    center = -r_wc @ v[:3, 3]
    d = np.stack([(corners[:, 0] - k[0, 2]) / k[0, 0], (corners[:, 1] - k[1, 2]) / k[1, 1],
                  np.ones(len(corners), dtype)], 1)
    if name == "ray_distance":
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.concatenate([center + (d * z) @ r_wc.T for z in (near, far)])


def _solid_planes(vertices):
    """Outward unit normals and offsets of a frustum's faces from its vertices (the outline's
    corners at the near depth, counter-clockwise in the image, then the same corners at the
    far depth): the near and far faces and one side face per outline edge."""
    m = len(vertices) // 2
    near, far = vertices[:m], vertices[m:]
    centroid = vertices.mean(0)
    planes = []
    for i in range(m):
        j = (i + 1) % m
        # A side face; for a degenerate edge (two equal corners) there is none.
        planes.append((near[i], np.cross(near[j] - near[i], far[i] - near[i])))
    for face in (near, far):  # Newell's normal: the plane of a camera depth
        nxt = np.roll(face, -1, axis=0)
        planes.append((face.mean(0), np.cross(face, nxt).sum(0)))
    out = []
    for p, n in planes:
        length = np.linalg.norm(n)
        if length == 0:
            continue
        n = n / length
        if n @ (centroid - p) > 0:
            n = -n
        out.append((n, n @ p))
    return out


def solid_unmatched(want, got, tol):
    """How far a port's frustum ``got`` is from being the oracle's solid ``want`` (both
    ``(V, 3)`` vertices): the oracle's vertices no port vertex lies within ``tol`` of, plus
    the port's vertices more than ``tol`` outside the oracle's solid. A corner on an edge
    (a hull that keeps collinear corners) is the same solid and counts nothing."""
    if len(want) == 0 or len(got) == 0:
        return len(want) + len(got)
    dist = np.linalg.norm(want[:, None, :] - got[None, :, :], axis=2)
    missing = int((dist.min(1) > tol).sum())
    extra = got[dist.min(0) > tol]  # the port's vertices that are none of the oracle's
    outside = np.zeros(len(extra), bool)
    for n, d in _solid_planes(want):
        outside |= extra @ n - d > tol
    return missing + int(outside.sum())


def unmatched(a, b, tol):
    """How many rows of ``a`` have no row of ``b`` within ``tol`` (Euclidean), plus how many
    rows of ``b`` have none in ``a``."""
    if len(a) == 0 or len(b) == 0:
        return len(a) + len(b)
    dist = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return int((dist.min(1) > tol).sum() + (dist.min(0) > tol).sum())


def views_case(seed):
    """A seeded case: 6–12 candidate ``frustums`` (float64 (8, 3)) of cameras standing in a
    5 m room and looking outward (yaw anywhere, pitch ±15°, horizontal half-angles 25–45°,
    near 0.3–1.2 m, far 1.5–4.5 m), and their camera ``centers`` (float64 (n, 3)). On odd
    seeds the last candidate is a copy of another moved until it touches a third one
    (within 1e-9 of the scale, either side): a verdict within contact noise."""
    rng = np.random.default_rng(np.random.PCG64(50_000 + seed))
    n = int(rng.integers(6, 13)) - seed % 2
    frustums, centers = [], []
    for _ in range(n):
        c = np.array([rng.uniform(-2.5, 2.5), rng.uniform(-2.5, 2.5), rng.uniform(1.2, 1.8)])
        yaw, pitch = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(-15, 15))
        fwd = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch),
                        np.sin(pitch)])
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        rot = np.column_stack([right, down, fwd])
        tx = np.tan(np.radians(rng.uniform(25, 45)))
        frustums.append(frustum(rng.uniform(0.3, 1.2), rng.uniform(1.5, 4.5), tx,
                                tx * rng.uniform(0.6, 0.8), rot, c))
        centers.append(c)
    if seed % 2:
        i, j = (int(v) for v in rng.choice(n, size=2, replace=False))
        shift = _to_contact(frustums[i], frustums[j], rng)
        frustums.append(frustums[i] + shift)
        centers.append(centers[i] + shift)
    return {"frustums": frustums, "centers": np.asarray(centers)}


def _to_contact(a, b, rng):
    """A translation of ``a`` that leaves it within 1e-9 of the scale of touching ``b``, on
    either side: along a random direction, from 40 m off to ``a``'s centroid on ``b``'s
    (where they overlap), bisected on the verdict."""
    from . import proximity

    u = rng.normal(0, 1, 3)
    u /= np.linalg.norm(u)
    base = b.mean(0) - a.mean(0)
    at = lambda t: a + base + (t - 40.0) * u  # noqa: E731
    lo, hi = 0.0, 40.0
    scale = max(np.abs(a).max(), np.abs(b).max())
    while hi - lo > 1e-10 * scale:
        mid = (lo + hi) / 2
        if proximity(at(mid), b)["intersect"]:
            hi = mid
        else:
            lo = mid
    t = lo if rng.random() < 0.5 else hi
    return base + (t - 40.0) * u


VIEWS_MISTAKES = (
    StageMistake("maximum_set", "a maximum independent set (most views), not the greedy "
                 "maximal one in candidate order"),
    StageMistake("reverse_order", "greedy in reverse candidate order"),
    StageMistake("index_tour", "the tour in index order, not nearest-neighbour"),
    StageMistake("open_tour", "an open tour (no gap from the last view back to the first)"),
)


#: Random candidate orders ``explains_selection`` tries for greedy in another order.
ORDER_DRAWS = 256
#: What a set chosen greedily in some other order is called.
ANOTHER_ORDER = "greedy in another candidate order (none of the listed mistakes)"


def _greedy(n, edges, order):
    adj = {i: set() for i in range(n)}
    for i, j in edges:
        adj[i].add(j)
        adj[j].add(i)
    chosen = []
    for i in order:
        if not adj[i] & set(chosen):
            chosen.append(i)
    return chosen


def greedy_allows(n, firm, near, chosen, order=None):
    """Whether ``chosen`` is the greedy selection (in ``order``, default candidate order) of
    some collision graph made of the ``firm`` pairs and any subset of the ``near`` ones:
    None if so, else why not. Exact and linear in the pairs, for any number of near-contact
    pairs: the subset that turns near pairs inside the set off and near pairs from a member
    to a later non-member on makes greedy choose ``chosen`` exactly when no firm pair lies
    inside it and every other view has a firm or near pair with an earlier member."""
    members = set(chosen)
    if len(members) != len(chosen) or any(not 0 <= v < n for v in chosen):
        return f"{sorted(chosen)} is not a set of views 0..{n - 1}"
    inside = sorted(e for e in firm if e[0] in members and e[1] in members)
    if inside:
        return f"views {inside[0][0]} and {inside[0][1]} collide beyond contact noise"
    rank = {v: k for k, v in enumerate(range(n) if order is None else order)}
    reach = set()
    for i, j in list(firm) + list(near):
        for a, b in ((i, j), (j, i)):
            if a in members and rank[a] < rank[b]:
                reach.add(b)
    for v in range(n):
        if v not in members and v not in reach:
            return (f"view {v} collides with no earlier chosen view, so greedy selection "
                    f"would take it")
    return None


def _largest_free(n, edges):
    """The largest sets of views with no pair in ``edges`` (all of one size)."""
    for size in range(n, 0, -1):
        found = [c for c in itertools.combinations(range(n), size)
                 if not any(i in c and j in c for i, j in edges)]
        if found:
            return found
    return [()]


def explains_selection(name, n, firm, near, chosen):
    """How likely selection mistake ``name`` (``VIEWS_MISTAKES``, or ``"another_order"``)
    is to choose the set ``chosen`` on a graph the near-contact pairs allow: 1 for greedy in
    reverse order when it can; 1/k for a largest set when ``chosen`` is one of k largest
    sets (a search among them may return any); for greedy in another order, the share of
    ``ORDER_DRAWS`` seeded random orders that choose it; 0 when it cannot."""
    if name == "reverse_order":
        return float(greedy_allows(n, firm, near, chosen, order=range(n - 1, -1, -1)) is None)
    if name == "another_order":
        orders = np.random.default_rng(np.random.PCG64(61_000)).permuted(
            np.tile(np.arange(n), (ORDER_DRAWS, 1)), axis=1)
        return float(np.mean([greedy_allows(n, firm, near, chosen, order=[int(v) for v in o])
                              is None for o in orders]))
    if name == "maximum_set":
        members = set(chosen)
        if any(i in members and j in members for i, j in firm):
            return 0.0
        # The graph that turns on every near pair but those inside the set keeps it
        # independent and leaves every other set the fewest views.
        edges = list(firm) + [(i, j) for i, j in near if not (i in members and j in members)]
        largest = _largest_free(n, edges)
        return 1.0 / len(largest) if tuple(sorted(members)) in largest else 0.0
    raise ValueError(f"not a selection mistake: {name!r}")


def mistaken_tour(name, chosen, centers):
    """``(trajectory, gaps)`` mistake ``name`` makes through the set ``chosen``."""
    tour, gaps = _tour(sorted(chosen), centers)
    if name == "index_tour":
        tour = sorted(chosen)
        gaps = _closing(tour)
    if name == "open_tour":
        gaps = gaps[:-1]
    return tour, gaps


def _closing(tour):
    m = len(tour)
    return [(tour[k], tour[(k + 1) % m]) for k in range(m)] if m > 1 else []


def _tour(views, centers):
    if not views:
        return [], []
    left = sorted(views[1:])
    tour = [views[0]]
    while left:
        d = [np.sum((centers[v] - centers[tour[-1]]) ** 2) for v in left]
        tour.append(left.pop(int(np.argmin(d))))
    return tour, _closing(tour)


def mistaken_views(name, n, edges, centers):
    """``(independent, trajectory, gaps)`` mistake ``name`` computes on the graph (any
    other name: the conventions)."""
    if name == "maximum_set":
        chosen = []
        for size in range(n, 0, -1):
            for subset in itertools.combinations(range(n), size):
                s = set(subset)
                if not any(i in s and j in s for i, j in edges):
                    chosen = list(subset)
                    break
            if chosen:
                break
    elif name == "reverse_order":
        chosen = _greedy(n, edges, range(n - 1, -1, -1))
    else:
        chosen = _greedy(n, edges, range(n))
    tour, gaps = _tour(chosen, centers)
    if name == "index_tour":
        tour = sorted(chosen)
        gaps = _closing(tour)
    if name == "open_tour":
        gaps = gaps[:-1]
    return chosen, tour, gaps


def tour_follows_the_rule(trajectory, independent, centers):
    """Whether ``trajectory`` visits exactly ``independent``, starts at its first view in
    candidate order (the lowest index) and always steps to a nearest remaining centre
    (within ``TOUR_REL``): the index of the first wrong step, or None."""
    if sorted(trajectory) != sorted(independent) or (
            independent and trajectory[0] != min(independent)):
        return 0
    left = set(trajectory[1:])
    for k in range(1, len(trajectory)):
        cur = trajectory[k - 1]
        d = {v: float(np.sum((centers[v] - centers[cur]) ** 2)) for v in left}
        nearest = min(d.values())
        if d[trajectory[k]] > nearest * (1 + TOUR_REL):
            return k
        left.discard(trajectory[k])
    return None
