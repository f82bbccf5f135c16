"""Region frustums and independent views through unseen.testing (SPEC.md §16.2, §16.3): the
oracle's bindings; a NumPy frustum port and five seeded wrong ones; independent-view ports
built on python-fcl's collision test (so its own verdicts on near-contact pairs) and on
the oracle's graph with each near-contact pair decided the other way, which must pass;
and four wrong selections. python-fcl's test is skipped, with the reason printed, where it
is not installed (python/requirements-stages.txt).
"""

import numpy as np
import pytest

import unseen
from unseen import testing as ut

SEEDS = range(20)


def test_the_frustum_binding_builds_and_refuses_bad_input():
    case = ut.frustum_case(0)
    cam = unseen.Camera(case["k"], case["viewmat"], case["width"], case["height"])
    f = unseen.frustum(cam, case["mask"], depth=case["depth"])
    assert f["vertices"].shape == (8, 3) and len(f["faces"]) == 6
    valid = case["mask"] & np.isfinite(case["depth"]) & (case["depth"] > 0)
    assert f["near"] == case["depth"][valid].min() and f["far"] == case["depth"][valid].max()
    g = unseen.frustum(cam, case["mask"], near=1.0, far=2.0, outline="hull")
    assert g["near"] == 1.0 and len(g["vertices"]) >= 8
    with pytest.raises(ValueError, match="either depth or both near and far"):
        unseen.frustum(cam, case["mask"], near=1.0)
    with pytest.raises(ValueError, match="outline"):
        unseen.frustum(cam, case["mask"], near=1.0, far=2.0, outline="circle")
    with pytest.raises(ValueError, match="mask: expected"):
        unseen.frustum(cam, case["mask"][1:].copy(), near=1.0, far=2.0)
    with pytest.raises(ValueError, match="the mask is empty"):
        unseen.frustum(cam, np.zeros_like(case["mask"]), near=1.0, far=2.0)
    with pytest.raises(ValueError, match="no valid depth"):
        unseen.frustum(cam, case["mask"], depth=np.zeros_like(case["depth"]))


def test_the_views_binding_selects_and_refuses_bad_input():
    case = ut.views_case(0)
    v = unseen.views(case["frustums"], case["centers"])
    assert v["trajectory"][0] == v["independent"][0]
    assert sorted(v["trajectory"]) == sorted(v["independent"])
    again = unseen.views(case["frustums"], case["centers"], edges=v["edges"])
    assert again == v
    with pytest.raises(ValueError, match="centers: expected"):
        unseen.views(case["frustums"], case["centers"][1:].copy())
    with pytest.raises(ValueError, match="no edge"):
        unseen.views(case["frustums"], case["centers"], edges=[(3, 1)])
    with pytest.raises(ValueError, match="twice or out of range"):
        unseen.views(case["frustums"], case["centers"], order=[0, 0])
    with pytest.raises(ValueError, match="order: expected non-negative indices"):
        unseen.views(case["frustums"], case["centers"], order=[-1])
    with pytest.raises(ValueError, match="listed twice"):
        unseen.views(case["frustums"], case["centers"], edges=[(0, 1), (0, 1)])
    bad = case["centers"].copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        unseen.views(case["frustums"], bad)


def test_a_tour_starting_elsewhere_fails():
    for seed in SEEDS:
        case = ut.views_case(seed)
        want = unseen.views(case["frustums"], case["centers"])
        if len(want["independent"]) < 2:
            continue
        ind = want["independent"]
        start = ind[-1]
        rest = sorted(set(ind) - {start})
        r = ut.compare_views(lambda f, c: {"independent": [start] + rest,
                                           "trajectory": [start] + rest}, case)
        assert not r.ok and "trajectory" in r.message(), r.message()
        return


def _frustum_port(mistake="none"):
    def port(mask, depth, k, viewmat, outline):
        return ut.mistaken_frustum(mistake, {"mask": mask, "depth": depth, "k": k,
                                             "viewmat": viewmat, "outline": outline})
    return port


def test_a_numpy_frustum_port_passes_in_float64_and_float32():
    for seed in SEEDS:
        r = ut.compare_frustum(_frustum_port(), seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"
        as_f32 = ut.compare_frustum(
            lambda m, d, k, v, o: ut.mistaken_frustum(
                "none", {"mask": m, "depth": d, "k": k, "viewmat": v, "outline": o},
                dtype=np.float32), seed=seed)
        assert as_f32.ok, f"seed {seed}, float32 arithmetic: {as_f32.message()}"


@pytest.mark.parametrize("mistake", [m.name for m in ut.FRUSTUM_MISTAKES])
def test_wrong_frustum_ports_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.FRUSTUM_MISTAKES if m.name == mistake)
    for seed in range(8):
        r = ut.compare_frustum(_frustum_port(mistake), seed=seed)
        assert not r.ok, f"seed {seed}: the mistake passed"
        # Measured: named on 8 of 8 seeds.
        assert r.cause == text, f"seed {seed}: {r.message()}"


def _own_frustum(mistake="none", collinear=False):
    """A frustum port written here, apart from the harness's emulations: camera-to-world by
    matrix inverse, its own monotone-chain hull (keeping collinear corners with
    ``collinear``), one mistake."""
    def turn(o, a, b):
        t = (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
        return t < 0 if collinear else t <= 0

    def hull(points):
        pts = sorted(set(map(tuple, points)))
        if len(pts) < 3:
            return pts

        def half(seq):
            out = []
            for p in seq:
                while len(out) >= 2 and turn(out[-2], out[-1], p):
                    out.pop()
                out.append(p)
            return out[:-1]
        return half(pts) + half(pts[::-1])

    def port(mask, depth, k, viewmat, outline):
        if mistake == "transposed":
            mask = mask.T
        ys, xs = np.nonzero(mask)
        if mistake == "pixel_centres":
            pts = np.stack([xs + 0.5, ys + 0.5], 1)
        else:
            pts = np.concatenate([np.stack([xs + dx, ys + dy], 1) for dx in (0, 1)
                                  for dy in (0, 1)])
        if outline == "bounding_box" or mistake == "no_far_edge":
            (x0, y0), (x1, y1) = pts.min(0), pts.max(0)
            if mistake == "no_far_edge":
                x1, y1 = x1 - 1, y1 - 1
            outline_pts = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        else:
            outline_pts = hull(pts)
        ok = np.isfinite(depth) & (depth > 0)
        if mistake != "all_depths":
            ok &= np.asarray(mask if mistake != "transposed" else mask.T)
        zs = depth[ok].astype(np.float64)
        if mistake == "fy_from_fx":
            k = np.diag([k[0, 0], k[0, 0], 1.0]) + np.outer(k[:2, 2].tolist() + [0], [0, 0, 1])
        cam_to_world = np.linalg.inv(viewmat)
        rays = np.linalg.inv(k) @ np.array([[u, v, 1.0] for u, v in outline_pts]).T
        if mistake == "ray_distance":
            rays = rays / np.linalg.norm(rays, axis=0)
        out = []
        for z in (zs.min(), zs.max()):
            p = np.vstack([rays * z, np.ones(rays.shape[1])])
            out.extend((cam_to_world @ p)[:3].T)
        return np.array(out)
    return port


def test_a_frustum_port_written_here_passes_with_or_without_collinear_corners():
    """Issue #70: a hull keeping collinear corners is the same solid; compared vertex for
    vertex it failed on their count. A corner moved off the surface still fails."""
    kept = 0
    for seed in SEEDS:
        r = ut.compare_frustum(_own_frustum(), seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"
        port = _own_frustum(collinear=True)
        r = ut.compare_frustum(port, seed=seed)
        assert r.ok, f"seed {seed}, collinear corners kept: {r.message()}"
        c = ut.frustum_case(seed)
        got = port(c["mask"], c["depth"], c["k"], c["viewmat"], c["outline"])
        want = unseen.frustum(ut.Camera(c["k"], c["viewmat"], c["width"], c["height"]),
                              c["mask"], depth=c["depth"], outline=c["outline"])["vertices"]
        kept += len(got) > len(want)
        if len(got) > len(want):  # a corner on an edge pushed out by 1e-4 of the scale
            extra = next(i for i in range(len(got))
                         if np.linalg.norm(want - got[i], axis=1).min() > 1e-6)
            bent = got.copy()
            bent[extra] += 1e-4 * np.abs(want).max() * (bent[extra] - want.mean(0)) / \
                np.linalg.norm(bent[extra] - want.mean(0))
            r = ut.compare_frustum(lambda *a, b=bent: b, c)
            assert not r.ok, f"seed {seed}: a corner off the surface passed"
    assert kept >= 5, kept  # hull seeds whose outline has collinear corners


@pytest.mark.parametrize("mistake", [m.name for m in ut.FRUSTUM_MISTAKES])
def test_frustum_ports_written_here_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.FRUSTUM_MISTAKES if m.name == mistake)
    for seed in range(8):
        r = ut.compare_frustum(_own_frustum(mistake), seed=seed)
        assert not r.ok, f"seed {seed}: the mistake passed"
        assert r.cause == text, f"seed {seed}: {r.message()}"


def _greedy_port(decide):
    """A selection port on its own collision verdicts ``decide(a, b, i, j)``."""
    def port(frustums, centers):
        n = len(frustums)
        edges = [(i, j) for i in range(n) for j in range(i + 1, n)
                 if decide(frustums[i], frustums[j], i, j)]
        ind, tour, gaps = ut.mistaken_views("none", n, edges, centers)
        return {"edges": edges, "independent": ind, "trajectory": tour, "gaps": gaps}
    return port


def test_near_contact_pairs_may_be_decided_either_way():
    flipped = 0
    for seed in SEEDS:
        case = ut.views_case(seed)
        fr = case["frustums"]
        near = {(i, j) for i in range(len(fr)) for j in range(i + 1, len(fr))
                if ut._near_contact(fr[i], fr[j], unseen.proximity(fr[i], fr[j]))}
        flipped += len(near)

        def decide(a, b, i, j, near=near):
            hit = unseen.proximity(a, b)["intersect"]
            return (not hit) if (i, j) in near else hit

        r = ut.compare_views(_greedy_port(decide), case)
        assert r.ok, f"seed {seed}: {r.message()}"
    # Measured: one near-contact pair on each odd seed (the generator's touching copy).
    assert flipped >= 10


def test_the_greedy_check_equals_enumerating_every_allowed_graph():
    # greedy_allows decides in one pass what trying each of the 2^k graphs decides: checked
    # against that enumeration on random graphs with up to 8 near-contact pairs.
    import itertools
    from unseen._views import _greedy, greedy_allows
    rng = np.random.default_rng(7)
    for _ in range(200):
        n = int(rng.integers(1, 8))
        pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
        kind = rng.integers(0, 3, len(pairs))  # 0 apart, 1 firm, 2 near
        firm = [e for e, k in zip(pairs, kind) if k == 1]
        near = [e for e, k in zip(pairs, kind) if k == 2][:8]
        allowed = {tuple(sorted(_greedy(n, firm + [e for e, on in zip(near, flips) if on],
                                        range(n))))
                   for flips in itertools.product((False, True), repeat=len(near))}
        for size in range(n + 1):
            for chosen in itertools.combinations(range(n), size):
                ok = greedy_allows(n, firm, near, list(chosen)) is None
                assert ok == (chosen in allowed), (n, firm, near, chosen)


def test_a_port_deciding_a_clear_pair_wrong_fails():
    case = ut.views_case(0)
    want = unseen.views(case["frustums"], case["centers"])
    first = tuple(want["edges"][0])

    def decide(a, b, i, j):
        return (i, j) != first and unseen.proximity(a, b)["intersect"]

    r = ut.compare_views(_greedy_port(decide), case)
    assert not r.ok and "edges" in r.message(), r.message()


@pytest.mark.parametrize("mistake", [m.name for m in ut.VIEWS_MISTAKES])
def test_wrong_selections_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.VIEWS_MISTAKES if m.name == mistake)
    judged, named = 0, 0
    for seed in SEEDS:
        case = ut.views_case(seed)
        n = len(case["frustums"])
        edges = [tuple(e) for e in unseen.views(case["frustums"], case["centers"])["edges"]]
        if ut.mistaken_views(mistake, n, edges, case["centers"]) == \
                ut.mistaken_views("none", n, edges, case["centers"]):
            continue  # the mistake changes nothing on this case

        def port(frustums, centers):
            # Its own collision graph: the judge asks again on the candidates relabelled.
            own = [tuple(e) for e in unseen.views(frustums, centers)["edges"]]
            ind, tour, gaps = ut.mistaken_views(mistake, n, own, centers)
            return {"independent": ind, "trajectory": tour, "gaps": gaps}

        r = ut.compare_views(port, case)
        assert not r.ok, f"seed {seed}: the mistake passed"
        judged += 1
        named += r.cause == text
        assert r.cause in ("", text), f"seed {seed}: {r.message()}"
    # Measured: named on every seed where it changes the result but seed 18, where the
    # reverse greedy set is the one largest set (either mistake chooses it for certain).
    assert judged >= 5 and named >= judged - 1, f"named on {named} of {judged}"


def _own_selection(mistake):
    """A selection port written here, apart from the harness's emulations: its own greedy
    pass (or a brute-force largest set), nearest-neighbour tour and gaps, one mistake."""
    import itertools

    def port(frustums, centers):
        n = len(frustums)
        hit = {(i, j): unseen.proximity(frustums[i], frustums[j])["intersect"]
               for i in range(n) for j in range(i + 1, n)}
        free = lambda views: not any(hit[(a, b)] for a, b in itertools.combinations(views, 2))  # noqa: E731
        if mistake == "maximum_set":
            chosen = next(list(c) for k in range(n, 0, -1)
                          for c in itertools.combinations(range(n), k) if free(c))
        else:
            chosen = []
            for v in (reversed(range(n)) if mistake == "reverse_order" else range(n)):
                if free(sorted(chosen + [v])):
                    chosen.append(v)
        if mistake == "index_tour":
            tour = sorted(chosen)
        else:
            left, tour = sorted(chosen), []
            tour.append(left.pop(0))
            while left:
                d = [float(((centers[v] - centers[tour[-1]]) ** 2).sum()) for v in left]
                tour.append(left.pop(int(np.argmin(d))))
        gaps = [(tour[k], tour[k + 1]) for k in range(len(tour) - 1)]
        if mistake != "open_tour" and len(tour) > 1:
            gaps.append((tour[-1], tour[0]))
        return {"independent": chosen, "trajectory": tour, "gaps": gaps}
    return port


@pytest.mark.parametrize("mistake", [m.name for m in ut.VIEWS_MISTAKES])
def test_selection_ports_written_here_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.VIEWS_MISTAKES if m.name == mistake)
    assert ut.compare_views(_own_selection("none"), seed=0).ok
    judged, named = 0, 0
    for seed in SEEDS:
        case = ut.views_case(seed)
        r = ut.compare_views(_own_selection(mistake), case)
        if r.ok:
            continue  # the mistake changes nothing on this case
        judged += 1
        named += r.cause == text
        # Unnamed only where another mistake chooses the same set (a reverse greedy set
        # that is also a largest one), never another named.
        assert r.cause in ("", text), f"seed {seed}: {r.message()}"
    # Measured: named on every judged seed but seed 18 (the reverse greedy set is the one
    # largest set there).
    assert judged >= 5 and named >= judged - 1, f"named on {named} of {judged}"


def test_python_fcl_selection_passes():
    fcl = pytest.importorskip("fcl", reason="python-fcl is not installed "
                              "(python/requirements-stages.txt)")
    flat = np.array([x for f in ut.FRUSTUM_FACES for x in (len(f), *f)])

    def decide(a, b, i, j):
        oa = fcl.CollisionObject(fcl.Convex(a, len(ut.FRUSTUM_FACES), flat))
        ob = fcl.CollisionObject(fcl.Convex(b, len(ut.FRUSTUM_FACES), flat))
        hit = fcl.CollisionResult()
        fcl.collide(oa, ob, fcl.CollisionRequest(), hit)
        return hit.is_collision

    for seed in SEEDS:
        r = ut.compare_views(_greedy_port(decide), seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"


def test_greedy_in_another_fixed_order_is_never_given_a_listed_name():
    """Issue #70: judged on one set, a selection greedy in another order was named a listed
    mistake wherever its set happened to be the reverse greedy one or a largest one. The
    judge now asks the port again on the candidates relabelled (``VIEWS_RELABELLINGS``) and
    weighs each hypothesis, greedy in some other order among them, by how likely it is to
    choose every set. Measured on seeds 0–39: a port greedy in a fixed shuffled label order
    fails on 32 and is called greedy in another order on 27, unnamed on 5, never a listed
    mistake (3 relabellings: 'reverse order' on 3 seeds)."""
    def port(frustums, centers):
        n = len(frustums)
        edges = {tuple(e) for e in unseen.views(frustums, centers)["edges"]}
        chosen = []
        for v in np.random.default_rng(7).permutation(n):
            if all(tuple(sorted((int(v), c))) not in edges for c in chosen):
                chosen.append(int(v))
        tour, gaps = ut.mistaken_tour("none", chosen, centers)
        return {"independent": chosen, "trajectory": tour, "gaps": gaps}

    called = 0
    for seed in range(40):
        r = ut.compare_views(port, seed=seed)
        assert r.cause in ("", ut.ANOTHER_ORDER), f"seed {seed}: {r.message()}"
        called += r.cause == ut.ANOTHER_ORDER
    assert called >= 20, called
