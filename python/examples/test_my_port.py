"""A test a GPU port copies: render and differentiate a seeded random scene with unseen (the
oracle) and with the port under test, and assert they agree within SPEC.md's tolerances.

To test your port, replace `port_render` / `port_backward` with calls into it (same gsplat
conventions: wxyz quaternions, log scales, logit opacities, (N, K, 3) SH, K and a
world-to-camera viewmat). As shipped, the "port" is unseen itself, so this file passes.
Run: `python -m pytest examples/test_my_port.py`.
"""

import numpy as np
import pytest

import unseen

# SPEC.md §8 tolerance levels: f32 colours/alpha against a reference
# (GOLDEN_COLOR_ATOL / GOLDEN_COLOR_RTOL) and gradients relative to the group's largest
# entry (GRAD_REL_TO_MAX) plus a relative term (GRAD_RTOL). A port with another summation
# order or fused multiply-adds should land well inside them.
COLOR_ATOL, COLOR_RTOL = 5e-6, 1.3e-6
GRAD_REL_TO_MAX, GRAD_RTOL = 2e-5, 2e-5


def port_render(scene, camera):
    """The port under test: return rgb (H, W, 3) and alpha (H, W) as float32."""
    out = unseen.render(**scene, camera=camera)
    return out["rgb"], out["alpha"]


def port_backward(scene, camera, grad_rgb):
    """The port under test: gradients of sum(grad_rgb * rgb) for every raw parameter."""
    g = unseen.backward(**scene, camera=camera, grad_rgb=grad_rgb)
    return {k: g[k] for k in ("means", "quats", "scales", "opacities", "sh")}


def seeded_scene(n, degree, seed):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    means = np.stack(
        [rng.uniform(-1.5, 1.5, n), rng.uniform(-1.0, 1.0, n), rng.uniform(2.0, 8.0, n)], 1
    )
    return dict(
        means=means.astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
        scales=rng.uniform(-4.0, -1.5, (n, 3)).astype(np.float32),
        opacities=rng.uniform(-3.0, 4.0, n).astype(np.float32),
        sh=(rng.normal(size=(n, k, 3)) * 0.4).astype(np.float32),
    )


def camera(width=64, height=48):
    """A turned and moved camera (a port that transposes the viewmat, or flips a sign in
    its translation, fails here)."""
    a, b = 0.1, -0.15
    r_wc = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]]) @ np.array(
        [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    )
    center = np.array([0.2, -0.1, -0.4])
    viewmat = np.eye(4)
    viewmat[:3, :3], viewmat[:3, 3] = r_wc.T, -r_wc.T @ center
    k = np.array([[60.0, 0.0, width / 2 + 0.5], [0.0, 58.0, height / 2 - 0.25], [0.0, 0.0, 1.0]])
    return unseen.Camera(k, viewmat, width, height)


def assert_close_to_group_max(got, want, name):
    scale = float(np.abs(want).max()) or 1.0
    err = np.abs(got.astype(np.float64) - want)
    bound = GRAD_REL_TO_MAX * scale + GRAD_RTOL * np.abs(want)
    worst = float((err - bound).max())
    assert worst <= 0.0, f"{name}: exceeds the tolerance by {worst:.3e} (largest |g| {scale:.3e})"


@pytest.mark.parametrize("degree", [0, 3])
def test_forward_matches_the_oracle(degree):
    scene, cam = seeded_scene(2000, degree, seed=1), camera()
    want = unseen.render(**scene, camera=cam)
    rgb, alpha = port_render(scene, cam)
    np.testing.assert_allclose(rgb, want["rgb"], atol=COLOR_ATOL, rtol=COLOR_RTOL)
    np.testing.assert_allclose(alpha, want["alpha"], atol=COLOR_ATOL, rtol=COLOR_RTOL)


@pytest.mark.parametrize("degree", [0, 3])
def test_backward_matches_the_oracle(degree):
    scene, cam = seeded_scene(2000, degree, seed=2), camera()
    grad_rgb = np.random.default_rng(3).normal(size=(cam.height, cam.width, 3))
    grad_rgb = grad_rgb.astype(np.float32)
    want = unseen.backward(**scene, camera=cam, grad_rgb=grad_rgb)
    got = port_backward(scene, cam, grad_rgb)
    for name in ("means", "quats", "scales", "opacities", "sh"):
        assert_close_to_group_max(got[name], want[name], name)
