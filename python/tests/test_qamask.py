"""The QA-Mask through unseen.testing (SPEC.md §15.1): the oracle's binding, NumPy ports of
the mask scene and of the mask (the mask from ``unseen.render`` and the projection, in
float64), and six seeded wrong ones, each named.
"""

import numpy as np
import pytest

import unseen
from unseen import testing as ut

SEEDS = range(12)


def _mask_scene(mistake=None):
    def port(trained, *, base, sh_degree):
        n, k = len(trained["means"]), (sh_degree + 1) ** 2
        sh = np.zeros((n, k, 3), np.float32)
        shift = np.float32(0.0 if mistake == "dc_unshifted" else 0.5)
        sh[:, 0] = (np.asarray(base, np.float32) - shift) / np.float32(ut.C0)
        if mistake == "rest_kept":
            m = min(k, trained["sh"].shape[1])
            sh[:, 1:m] = trained["sh"][:, 1:m]
        return dict(trained, sh=sh)
    return port


def _mask(mistake=None):
    def port(tuned, camera, *, base, target):
        bg = target if mistake == "target_background" else base
        r = unseen.render(**tuned, camera=camera, background=list(bg))
        if mistake == "opacity":
            return 1.0 - r["alpha"]
        if mistake == "mean_channel":
            return r["rgb"].mean(-1)
        return ut.project(r["rgb"], base, target, clamp=mistake != "no_clamp")
    return port


def test_the_oracle_binding_builds_and_renders_and_refuses_bad_input():
    c = ut.qa_mask_case(0)
    s = unseen.qa_mask(**c["trained"], base=[1.0, 0.0, 0.0], sh_degree=5)
    assert s["sh"].shape[1] == 36 and (s["sh"][:, 1:] == 0).all()
    assert (s["means"] == c["trained"]["means"]).all()
    m = unseen.qa_mask(**c["tuned"], camera=c["camera"], base=list(c["base"]),
                       target=list(c["target"]))["mask"]
    assert m.shape == (72, 96) and (m >= 0).all() and (m <= 1).all()
    with pytest.raises(ValueError, match="colours"):
        unseen.qa_mask(**c["trained"], base=[2.0, 0.0, 0.0])


def test_numpy_ports_pass():
    for seed in SEEDS:
        r = ut.compare_qa_mask({"mask_scene": _mask_scene(), "mask": _mask()}, seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"


@pytest.mark.parametrize("mistake", [m.name for m in ut.QA_MASK_MISTAKES])
def test_wrong_ports_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.QA_MASK_MISTAKES if m.name == mistake)
    part = "mask_scene" if mistake in ("dc_unshifted", "rest_kept") else "mask"
    port = {part: (_mask_scene if part == "mask_scene" else _mask)(mistake)}
    for seed in range(6):
        r = ut.compare_qa_mask(port, seed=seed)
        assert not r.ok, f"seed {seed}: the mistake passed"
        # Measured: each fails and is named on 6 of 6 seeds.
        assert r.cause == text, f"seed {seed}: {r.message()}"
