"""Densification through unseen.testing (SPEC.md §14.3): the oracle's binding, a NumPy port
(which must pass), six seeded wrong ones (each named) and the real third-party strategy,
gsplat's ``DefaultStrategy`` (its grow and prune steps on CPU, its normal draws replaced
by the case's), on 20 seeds of ``densify_case``. gsplat's test is skipped, with the reason
printed, where torch or gsplat is not installed (python/requirements-port.txt).
"""

import re

import numpy as np
import pytest

import unseen
from unseen import testing as ut

SEEDS = range(20)
KEYS = ("means", "quats", "scales", "opacities", "sh")


def _reference_port(mistake=None):
    def port(scene, grad_accum, count, *, extent, world_prune, normals):
        case = dict(scene, grad_accum=grad_accum, count=count, extent=extent,
                    world_prune=world_prune, normals=normals)
        return ut.densify_reference(case, mistake)
    return port


def test_the_oracle_binding_densifies_and_refuses_bad_input():
    c = ut.densify_case(0)
    args = [c[k] for k in KEYS] + [c["grad_accum"], c["count"]]
    out = unseen.densify(*args, extent=c["extent"], world_prune=True, normals=c["normals"])
    n = len(c["means"])
    assert len(out["means"]) == n + out["cloned"] + out["split"] - out["pruned"]
    assert out["sh"].shape[1:] == c["sh"].shape[1:]
    with pytest.raises(ValueError, match="normals: expected"):
        unseen.densify(*args, extent=c["extent"], world_prune=True,
                       normals=c["normals"][:, 1:].copy())
    with pytest.raises(ValueError, match="count: expected"):
        unseen.densify(*args[:-1], c["count"].astype(np.int64), extent=c["extent"],
                       world_prune=True, normals=c["normals"])
    with pytest.raises(ValueError, match="extent"):
        unseen.densify(*args, extent=0.0, world_prune=True, normals=c["normals"])


def test_a_numpy_port_passes_and_the_thresholds_are_set_aside():
    for seed in SEEDS:
        r = ut.compare_densify(_reference_port(), seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"
        # The generator puts three Gaussians on a threshold.
        assert r.excluded["near a threshold"] >= 3


@pytest.mark.parametrize("mistake", [m.name for m in ut.DENSIFY_MISTAKES])
def test_wrong_ports_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.DENSIFY_MISTAKES if m.name == mistake)
    for seed in range(8):
        r = ut.compare_densify(_reference_port(mistake), seed=seed)
        assert not r.ok, f"seed {seed}: the mistake passed"
        # Measured: named on 8 of 8 seeds.
        assert r.cause == text, f"seed {seed}: {r.message()}"


def test_a_port_moving_children_fails_on_values():
    def port(scene, grad_accum, count, **kw):
        out = _reference_port()(scene, grad_accum, count, **kw)
        child = np.nonzero(~np.isin(out["scales"].view(np.uint32),
                                    scene["scales"].view(np.uint32)).all(1))[0]
        out["means"][child] += 1e-3
        return out

    r = ut.compare_densify(port, seed=1)
    assert not r.ok and "values" in r.message(), r.message()


def test_gsplat_default_strategy_passes():
    port = _gsplat_port(with_moments=False)
    for seed in SEEDS:
        r = ut.compare_densify(port, seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"


def _gsplat_port(with_moments=True, mistake=None, **strategy_kw):
    """gsplat's DefaultStrategy (grow, then prune; ``strategy_kw`` its options) on CPU, its
    torch.randn replaced by the case's draws; with ``with_moments`` real
    torch.optim.Adam optimizers carry the case's moments through it, and ``mistake`` (test
    doubles of MOMENT_MISTAKES) spoils them after."""
    torch = pytest.importorskip("torch", reason="torch is not installed "
                                "(python/requirements-port.txt)")
    pytest.importorskip("gsplat", reason="gsplat is not installed "
                        "(python/requirements-port.txt)")
    import gsplat.strategy.default as gd
    from gsplat.strategy import DefaultStrategy

    def split_sh(d):
        return {"means": d["means"], "quats": d["quats"], "scales": d["scales"],
                "opacities": d["opacities"], "sh0": d["sh"][:, :1], "shN": d["sh"][:, 1:]}

    def join_sh(d):
        out = {k: d[k] for k in ("means", "quats", "scales", "opacities")}
        out["sh"] = np.concatenate([d["sh0"], d["shN"]], 1)
        return out

    def run(scene, grad_accum, count, extent, world_prune, normals, moments):
        # INRIA's thresholds by default; screen-space tests off.
        strategy = DefaultStrategy(**strategy_kw)
        params = {k: torch.nn.Parameter(torch.from_numpy(v.copy()), requires_grad=False)
                  for k, v in split_sh(scene).items()}
        optimizers = {}
        if moments is not None:
            m, v = split_sh(moments[0]), split_sh(moments[1])
            for k, p in params.items():
                opt = torch.optim.Adam([p], lr=1e-3, eps=1e-15)
                opt.state[p] = {"step": torch.tensor(10.0),
                                "exp_avg": torch.from_numpy(m[k].copy()),
                                "exp_avg_sq": torch.from_numpy(v[k].copy())}
                optimizers[k] = opt
        state = {"grad2d": torch.from_numpy(grad_accum.copy()),
                 "count": torch.from_numpy(count.astype(np.float32)),
                 "scene_scale": extent, "radii": None}
        # After the first opacity reset the large-Gaussian prune is on, as ours.
        step = (strategy.reset_every if world_prune else strategy.refine_start_iter) \
            + strategy.refine_every
        split = gd.split

        def split_with_the_cases_normals(params, optimizers, state, mask, **kw):
            z = torch.from_numpy(normals[:, torch.where(mask)[0].numpy()].copy())
            randn, torch.randn = torch.randn, lambda *a, **k: z
            try:
                return split(params, optimizers, state, mask, **kw)
            finally:
                torch.randn = randn

        gd.split = split_with_the_cases_normals
        try:
            strategy._grow_gs(params, optimizers, state, step)
            strategy._prune_gs(params, optimizers, state, step)
        finally:
            gd.split = split
        out = join_sh({k: params[k].detach().numpy() for k in params})
        if moments is not None:
            for name in ("exp_avg", "exp_avg_sq"):
                out[name] = join_sh({k: optimizers[k].state[params[k]][name].numpy()
                                     for k in params})
        return out

    if not with_moments:
        def port(scene, grad_accum, count, *, extent, world_prune, normals):
            return run(scene, grad_accum, count, extent, world_prune, normals, None)
        return port

    def port(scene, grad_accum, count, *, extent, world_prune, normals, moments):
        out = run(scene, grad_accum, count, extent, world_prune, normals, moments)
        n_in, n_out = len(scene["means"]), len(out["means"])
        for j, name in enumerate(("exp_avg", "exp_avg_sq")):
            given = moments[j]
            for k in KEYS:
                if mistake == "reset_moments":
                    out[name][k] = np.zeros_like(out[name][k])
                elif mistake == "unmoved_moments":
                    o = np.zeros_like(out[name][k])
                    o[:min(n_in, n_out)] = given[k][:min(n_in, n_out)]
                    out[name][k] = o
                elif mistake == "parent_moments":
                    # Every row takes its source Gaussian's moments (the SH tag names it:
                    # a test double may read it, a port could not).
                    src = out["sh"][:, -1, 2].astype(int)
                    out[name][k] = given[k][src]
        return out
    return port


def test_gsplat_default_strategy_carries_adams_moments():
    for seed in SEEDS:
        r = ut.compare_densify(_gsplat_port(), seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"


@pytest.mark.parametrize("mistake", [m.name for m in ut.MOMENT_MISTAKES])
def test_moments_carried_wrong_fail_with_the_mistake_named(mistake):
    text = next(m.text for m in ut.MOMENT_MISTAKES if m.name == mistake)
    for seed in range(8):
        r = ut.compare_densify(_gsplat_port(mistake=mistake), seed=seed)
        assert not r.ok, f"seed {seed}: the mistake passed"
        assert r.cause == text, f"seed {seed}: {r.message()}"


def test_gsplat_made_wrong_fails_with_the_mistake_named():
    # Two of DENSIFY_MISTAKES made with gsplat's own strategy rather than the harness's
    # emulation: its mean gradient with every view count taken as one (the summed
    # gradient), and its size test off (grow_scale3d = 0: every hot Gaussian split).
    plain = _gsplat_port(with_moments=False)
    ports = {
        "sum_not_mean": lambda scene, grad_accum, count, **kw: plain(
            scene, grad_accum, np.ones_like(count), **kw),
        "no_size_test": _gsplat_port(with_moments=False, grow_scale3d=0.0),
    }
    for mistake, port in ports.items():
        text = next(m.text for m in ut.DENSIFY_MISTAKES if m.name == mistake)
        for seed in range(8):
            r = ut.compare_densify(port, seed=seed)
            assert not r.ok, f"{mistake}, seed {seed}: the mistake passed"
            assert r.cause == text, f"{mistake}, seed {seed}: {r.message()}"


def _span(text):
    """The interval a threshold hypothesis states ("of a–b", "of ≥ a", "of ≤ b")."""
    m = re.search(r" of (≥ |≤ )?([0-9.e+-]+)(?:–([0-9.e+-]+))?[ ,]", text)
    lo = float(m.group(2))
    if m.group(1):
        return (lo, np.inf) if m.group(1) == "≥ " else (0.0, lo)
    return lo, float(m.group(3))


def test_gsplat_with_other_settings_fails_with_the_threshold_it_used():
    """gsplat's strategy set otherwise than INRIA (issue #70: caught, never named): the
    judge infers from the port's decisions the interval a threshold must lie in, and names
    the threshold, with that interval, which explains every decision. Measured: named on
    every seed where the setting changes a decision (12 of 12; prune_scale3d only acts on
    the odd seeds, with the large-Gaussian prune on; a scene_scale is told from
    grow_scale3d only there)."""
    text = ut.DENSIFY_THRESHOLD_TEXT
    plain = _gsplat_port(with_moments=False)

    def doubled_extent(scene, g, c, *, extent, **kw):
        return plain(scene, g, c, extent=2 * extent, **kw)

    # (port, what is named and the value its interval holds on even / odd seeds); None:
    # the setting changes no decision there.
    ports = [
        ({"grow_grad2d": 8e-4}, [(text["grad_threshold"], 8e-4)] * 2),
        ({"grow_grad2d": 1e-4}, [(text["grad_threshold"], 1e-4)] * 2),
        ({"prune_opa": 0.02}, [(text["min_opacity"], 0.02)] * 2),
        ({"grow_scale3d": 0.03}, [(text["percent_dense"], 0.03)] * 2),
        ({"prune_scale3d": 0.3}, [None, (text["world_prune_fraction"], 0.3)]),
        (doubled_extent, [(text["percent_dense"], 0.02), ("an extent (scene_scale) of", 2.0)]),
    ]
    for settings, expected in ports:
        port = settings if callable(settings) else _gsplat_port(with_moments=False, **settings)
        for seed in range(8):
            r = ut.compare_densify(port, seed=seed)
            if expected[seed % 2] is None:
                assert r.ok, f"{settings}, seed {seed}: {r.message()}"
                continue
            named, value = expected[seed % 2]
            assert not r.ok, f"{settings}, seed {seed}: passed"
            assert r.cause.startswith(named), f"{settings}, seed {seed}: {r.message()}"
            lo, hi = _span(r.cause)
            assert lo <= value <= hi, f"{settings}, seed {seed}: {r.cause}"


def test_gsplat_revised_opacity_fails_named():
    text = next(m.text for m in ut.DENSIFY_VALUE_MISTAKES if m.name == "revised_opacity")
    port = _gsplat_port(with_moments=False, revised_opacity=True)
    for seed in range(8):
        r = ut.compare_densify(port, seed=seed)
        if _splits(r) == 0:
            continue
        assert not r.ok and r.cause == text, f"seed {seed}: {r.message()}"


def _splits(report):
    """How many Gaussians the oracle split (from the report's title)."""
    return int(re.search(r", (\d+) split", report.what).group(1))


def _twin_port(scene, grad_accum, count, **kw):
    """A port whose two split children sit at one point: every second child moved onto the
    first child of its Gaussian (found by the tag in the last SH coefficient, as a reader
    of the output would), written apart from the harness's emulations."""
    out = _reference_port()(scene, grad_accum, count, **kw)
    tags = out["sh"][:, -1, 2]
    shrunk = ~np.isin(out["scales"].view(np.uint32), scene["scales"].view(np.uint32)).all(1)
    first = {}
    for r in np.nonzero(shrunk)[0]:
        t = float(tags[r])
        if t in first:
            out["means"][r] = out["means"][first[t]]
        else:
            first[t] = r
    return out


def test_twin_children_fail_one_to_one_on_every_seed_that_splits():
    """Issue #70: a judge that accepted a child near *any* of the oracle's children let a
    port whose two children coincide pass (12 of 12 seeds). Matched one to one, copy c to
    normals[c], it fails wherever the oracle splits, and the twin mistake is named."""
    text = next(m.text for m in ut.DENSIFY_VALUE_MISTAKES if m.name == "twin_children")
    splitting = 0
    for seed in SEEDS:
        r = ut.compare_densify(_twin_port, seed=seed)
        if _splits(r) == 0:
            assert r.ok, f"seed {seed}: {r.message()}"
            continue
        splitting += 1
        assert not r.ok, f"seed {seed}: twin children passed"
        assert r.cause == text, f"seed {seed}: {r.message()}"
    assert splitting >= 10


@pytest.mark.parametrize("mistake", [m.name for m in ut.DENSIFY_VALUE_MISTAKES])
def test_child_value_mistakes_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.DENSIFY_VALUE_MISTAKES if m.name == mistake)
    for seed in range(8):
        r = ut.compare_densify(_reference_port(mistake), seed=seed)
        if _splits(r) == 0:
            continue
        assert not r.ok, f"seed {seed}: the mistake passed"
        assert r.cause == text, f"seed {seed}: {r.message()}"
