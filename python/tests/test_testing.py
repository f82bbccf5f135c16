"""unseen.testing's own behaviour, with unseen as the port (no torch needed): a port that
differs by float noise passes, every kind of failure is reported in words."""

import numpy as np
import pytest

import unseen
from unseen import testing


def noisy(scene, seed):
    """The scene's means, scales and rotations moved by ±1.2e-7 relative: what another
    summation order or FMA does to a port's intermediates."""
    rng = np.random.default_rng(seed)
    out = dict(scene)
    for k in ("means", "scales", "quats"):
        v = scene[k]
        out[k] = (v * (1 + 1.2e-7 * rng.uniform(-1, 1, v.shape))).astype(np.float32)
    return out


@pytest.mark.parametrize("family", ["random", "near_plane", "rolled", "clamp"])
@pytest.mark.parametrize("seed", [0, 1])
def test_float_noise_passes_with_depth(family, seed):
    scene, cam = testing.scene(3000, 3, seed, width=96, height=80, family=family)

    def port(s, c):
        return unseen.render(**noisy(s, seed), camera=c, conventions="gsplat")

    testing.compare_render(port, scene, cam, conventions="gsplat",
                           outputs=("rgb", "alpha", "depth"))


def test_failures_are_reported_in_words():
    scene, cam = testing.scene(500, 1, 0, width=48, height=32)
    good = unseen.render(**scene, camera=cam)
    with pytest.raises(AssertionError, match=r"alpha: the port returned no such output"):
        testing.compare_render({"rgb": good["rgb"]}, scene, cam)
    with pytest.raises(AssertionError, match=r"rgb: the port returned shape \(32, 48\), the oracle \(32, 48, 3\)"):
        testing.compare_render({"rgb": good["alpha"], "alpha": good["alpha"]}, scene, cam)
    with pytest.raises(ValueError, match="outputs: expected names among"):
        testing.compare_render(good, scene, cam, outputs=("expected_depth",))
    r = testing.compare_render({"rgb": good["rgb"], "alpha": good["alpha"] + 0.01}, scene, cam,
                               check=False)
    assert not r.ok and r.failures[0].quantity == "alpha" and r.diagnosed
    assert "likely cause: none of the known mistakes" in r.message()
    hard, hcam = testing.scene(2000, 1, 0, width=48, height=32, family="hard")
    r = testing.compare_render(unseen.render(**hard, camera=hcam), hard, hcam, check=False,
                               max_excluded_fraction=0.001)
    assert r.excluded_fraction > 0.001
    assert [f.quantity for f in r.failures] == ["excluded pixels"]
    assert not r.diagnosed and "likely cause" not in r.message()
