"""The frustum collision test through unseen.testing (SPEC.md §16): the oracle's binding, four
seeded wrong ports (each must fail with its mistake named) and a real third-party one,
python-fcl's convex-convex collision and distance (FCL's GJK), on 20 seeds of
``collide_case``. python-fcl's test is skipped, with the reason printed, where it is not
installed (python/requirements-stages.txt).
"""

import numpy as np
import pytest

import unseen
from unseen import testing as ut

SEEDS = range(20)


def test_the_oracle_binding_answers_and_refuses_bad_input():
    a = ut.frustum(0.1, 2.0, 0.5, 0.4)
    far = unseen.proximity(a, a + [10.0, 0.0, 0.0])
    assert not far["intersect"] and far["lower_bound"] <= far["distance"]
    assert abs(far["distance"] - (10.0 - 2 * 0.5 * 2.0)) < 1e-9
    assert unseen.proximity(a, a)["intersect"]
    with pytest.raises(ValueError, match="a: expected"):
        unseen.proximity(a[:, :2].copy(), a)
    bad = a.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="b: .*not finite"):
        unseen.proximity(a, bad)


def test_the_oracle_passes_and_the_case_can_judge():
    port = lambda a, b, faces: unseen.proximity(a, b)["intersect"]  # noqa: E731
    for seed in range(4):
        r = ut.compare_collide(port, seed=seed)
        assert r.ok, r.message()
        assert 0 < r.excluded_fraction <= ut.MAX_SET_ASIDE, r.message()


@pytest.mark.parametrize("mistake", [m.name for m in ut.COLLIDE_MISTAKES])
def test_wrong_ports_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.COLLIDE_MISTAKES if m.name == mistake)
    port = lambda a, b, faces: ut.mistaken_verdict(mistake, a, b, faces)  # noqa: E731
    for seed in range(8):
        r = ut.compare_collide(port, seed=seed)
        assert not r.ok, f"seed {seed}: the mistake passed"
        assert r.cause == text, f"seed {seed}: {r.message()}"


def test_python_fcl_passes():
    fcl = pytest.importorskip("fcl", reason="python-fcl is not installed "
                              "(python/requirements-stages.txt)")

    def port(a, b, faces):
        flat = np.array([x for f in faces for x in (len(f), *f)])
        oa = fcl.CollisionObject(fcl.Convex(a, len(faces), flat))
        ob = fcl.CollisionObject(fcl.Convex(b, len(faces), flat))
        hit = fcl.CollisionResult()
        fcl.collide(oa, ob, fcl.CollisionRequest(), hit)
        if hit.is_collision:
            return {"intersect": True, "distance": 0.0}
        d = fcl.DistanceResult()
        fcl.distance(oa, ob, fcl.DistanceRequest(), d)
        return {"intersect": False, "distance": d.min_distance}

    for seed in SEEDS:
        r = ut.compare_collide(port, seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"
