"""The audit's metric panel beyond PSNR and SSIM (SPEC.md §20.7): GMSD (Xue et al. 2014) and
the detail ratio, as ``unseen.gradient_similarity`` computes them for the evaluation's pixel
classes. GMSD over every pixel is checked against piq 0.8's ``gmsd`` (the published
definition, float64) and the per-class sums against a NumPy oracle written here from the
definition; piq's test is skipped, with the reason printed, where piq is not installed
(python/requirements-port.txt).
"""

import numpy as np
import pytest

import unseen

#: The cases: image sizes (odd sides included: GMSD pads them with a zero row or column).
SIZES = [(60, 80), (61, 79), (33, 47), (2, 3)]


def _pair(seed, h, w):
    """A render-like texture and a truth that differs by blur, noise and a shift."""
    rng = np.random.default_rng(np.random.PCG64(80_000 + seed))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    t = np.stack([0.5 + 0.3 * np.sin(rng.uniform(0.05, 0.6) * xx + rng.uniform(0.05, 0.6) * yy
                                     + rng.uniform(0, 6)) for _ in range(3)], -1)
    t += 0.05 * rng.standard_normal(t.shape)
    r = 0.5 * t + 0.5 * np.roll(t, 1, axis=1) + 0.03 * rng.standard_normal(t.shape)
    return (np.clip(r, -0.1, 1.1).astype(np.float32), np.clip(t, 0, 1).astype(np.float32),
            rng.random((h, w)) < 0.4)


def _blocks(img, mode="constant"):
    """GMSD's half-resolution luma and Prewitt gradient energy, in float64 (``mode``: the
    padding, zeros for GMSD, ``"edge"`` for the detail ratio)."""
    x = np.clip(img.astype(np.float64), 0, 1) @ np.array([0.299, 0.587, 0.114])
    h, w = x.shape
    p = np.zeros((h + h % 2, w + w % 2))
    p[:h, :w] = x
    b = (p[0::2, 0::2] + p[1::2, 0::2] + p[0::2, 1::2] + p[1::2, 1::2]) / 4
    q = np.pad(b, 1, mode=mode)
    gx = sum(q[1 + k:q.shape[0] - 1 + k, 2:] - q[1 + k:q.shape[0] - 1 + k, :-2]
             for k in (-1, 0, 1)) / 3
    gy = sum(q[2:, 1 + k:q.shape[1] - 1 + k] - q[:-2, 1 + k:q.shape[1] - 1 + k]
             for k in (-1, 0, 1)) / 3
    return gx * gx + gy * gy


def _numpy_sums(r, t, mask):
    er, et = _blocks(r), _blocks(t)
    c = 170 / 255 ** 2
    dr, dt = _blocks(r, "edge"), _blocks(t, "edge")
    s = (2 * np.sqrt(er * et) + c) / (er + et + c)
    h, w = mask.shape
    inside = np.zeros(er.shape)
    np.add.at(inside, (np.arange(h)[:, None] // 2, np.arange(w)[None, :] // 2), 1.0)
    weight = np.zeros(er.shape)
    ys, xs = np.nonzero(mask)
    np.add.at(weight, (ys // 2, xs // 2), 1.0)
    weight /= inside
    d = 1 - s
    return {"weight": weight.sum(), "gms_deficit": (weight * d).sum(),
            "gms_deficit_squares": (weight * d * d).sum(),
            "render_gradient_energy": (weight * dr).sum(),
            "truth_gradient_energy": (weight * dt).sum()}


@pytest.mark.parametrize("size", SIZES, ids=[f"{h}x{w}" for h, w in SIZES])
def test_gmsd_over_every_pixel_is_piqs(size):
    torch = pytest.importorskip("torch", reason="torch is not installed "
                                "(python/requirements-port.txt)")
    piq = pytest.importorskip("piq", reason="piq is not installed (python/requirements-port.txt)")
    for seed in range(5):
        r, t, _ = _pair(seed, *size)
        got = unseen.gradient_similarity(r, t)["gmsd"]
        to = lambda a: torch.from_numpy(np.clip(a, 0, 1).astype(np.float64)).permute(2, 0, 1)[None]  # noqa: E731
        want = float(piq.gmsd(to(r), to(t), data_range=1.0, reduction="none")[0])
        # Both float64: sums in other orders, and piq's two-pass deviation against our
        # pooled one over the deficit 1 − similarity (its rounding about blocks·u·d̄²/GMSD,
        # d̄ the mean deficit): 1e-9 relative.
        assert got == pytest.approx(want, rel=1e-9), (seed, got, want)


@pytest.mark.parametrize("size", SIZES, ids=[f"{h}x{w}" for h, w in SIZES])
def test_class_sums_are_the_definitions(size):
    for seed in range(5):
        r, t, mask = _pair(seed, *size)
        got = unseen.gradient_similarity(r, t, mask=mask)
        want = _numpy_sums(r, t, mask)
        for k, v in want.items():
            assert got["sums"][k] == pytest.approx(v, rel=1e-12, abs=1e-15), (seed, k)
        every = unseen.gradient_similarity(r, t)["sums"]
        # Every pixel weighs every block once.
        assert every["weight"] == pytest.approx(got["similarity"].size, rel=1e-15)
        w = want["weight"]
        gmsd = np.sqrt(max(want["gms_deficit_squares"] / w - (want["gms_deficit"] / w) ** 2, 0))
        assert got["gmsd"] == pytest.approx(gmsd, rel=1e-9)


def test_the_detail_ratio_sees_averaging():
    """Two sharp generations of one surface that disagree, averaged (what a scene fits to
    conflicting generations), score a better PSNR against the truth than the other sharp
    generation does, but lose detail: the ratio falls to about a half, and GMSD rises."""
    rng = np.random.default_rng(7)
    t = rng.random((40, 60, 3)).astype(np.float32)
    other = rng.random((40, 60, 3)).astype(np.float32)
    blend = ((t + other) / 2).astype(np.float32)
    same = unseen.gradient_similarity(t, t)
    assert same["detail_ratio"] == 1.0 and same["gmsd"] == 0.0
    mse = lambda a: float(((a - t) ** 2).mean())  # noqa: E731
    assert mse(blend) < mse(other)
    assert 0.4 < unseen.gradient_similarity(blend, t)["detail_ratio"] < 0.7
    assert 0.8 < unseen.gradient_similarity(other, t)["detail_ratio"] < 1.25
    assert unseen.gradient_similarity(blend, t)["gmsd"] > 0.05


def test_bad_input_is_refused():
    r, t, mask = _pair(0, 20, 30)
    with pytest.raises(ValueError, match="y: expected"):
        unseen.gradient_similarity(r, t[:, :29].copy())
    with pytest.raises(ValueError, match="mask: expected"):
        unseen.gradient_similarity(r, t, mask=mask[:, :29].copy())
    with pytest.raises(ValueError, match="x: expected"):
        unseen.gradient_similarity(r[..., :2].copy(), t)
