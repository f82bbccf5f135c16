"""The training loss for ports: ``compare_loss``'s cases, conventions and known mistakes
(SPEC.md §13, §14.1).

INRIA's loss is ``0.8·L1 + 0.2·(1 − SSIM)`` with SSIM over an 11×11 Gaussian window
(σ = 1.5), ``C1 = 0.01²``, ``C2 = 0.03²``, zero padding of 5 and the mean over every pixel
(``conventions="inria"``). Libraries differ in the border: pytorch-msssim averages only the
pixels whose window lies inside the image (``"valid"``), torchmetrics mirrors the image by
the window's radius and averages every pixel (``"reflect"``); the border shifts the mean by
about 1e-3, far beyond rounding, so a port is judged under the convention it follows.
"""

import numpy as np

from ._stage import StageMistake

#: |port − oracle| allowed on the mean SSIM. Float32 ports form σ² = E[x²] − μ² with
#: cancellation (up to a few ulps of E[x²] per pixel, × 1/C2 ≈ 1.1e3 in SSIM where the
#: image is flat); over an image these errors average out. Measured on ``loss_case``
#: seeds 0–19 against the oracle's float64: INRIA's formula in torch float32 ≤ 1.4e-6,
#: pytorch-msssim ≤ 1.5e-6, torchmetrics ≤ 2.4e-6; 2e-5 is 8× the largest, and every
#: known mistake moves the mean by more than 100× it.
SSIM_ATOL = 2e-5
#: |port − oracle| allowed per pixel of the SSIM map. A float32 variance
#: ``E[x²] − μ²`` is off by about two roundings of ``E[x²]`` (≤ 1 on [0, 1] images),
#: ``2u``, and SSIM moves by at most ``1/C2`` per unit of each of its three (co)variances
#: (twice for the covariance): ``4·2u/C2`` = 5.3e-4. Measured on ``loss_case`` seeds 0–19
#: against the oracle's float64 map: INRIA's formula in torch float32 ≤ 9.3e-5,
#: torchmetrics' full image ≤ 9.2e-5.
SSIM_MAP_ATOL = 5e-4
#: L1, a float32 mean of |x − y| against the oracle's float64 one: relative.
L1_RTOL = 1e-5
#: INRIA's weights (SPEC.md §14.1).
LAMBDA_DSSIM = 0.2
#: A port's gradient of INRIA's loss with respect to the rendered image may differ by this
#: share of the oracle's largest gradient value: SSIM's variances cancel (E[x²] − E[x]²) in
#: float32 (measured: INRIA's formula under torch autograd within 5.3e-5 on 20 seeds; ×4).
GRAD_ATOL_REL = 2e-4
CONVENTIONS = ("inria", "valid", "reflect")


def loss_case(seed):
    """A seeded pair of float32 ``(H, W, 3)`` images in [0, 1]: a render-like texture (waves
    and noise) and a target that differs by noise, a shift, a brightness change, flat
    patches and clipped highlights; sizes from 40×52 to 97×136."""
    rng = np.random.default_rng(np.random.PCG64(30_000 + seed))
    h, w = 40 + int(rng.integers(0, 58)), 52 + int(rng.integers(0, 85))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    x = np.zeros((h, w, 3))
    for c in range(3):
        for _ in range(3):
            f, g, p = rng.uniform(0.02, 0.4, 2).tolist() + [rng.uniform(0, 6.3)]
            x[..., c] += rng.uniform(0.05, 0.3) * np.sin(f * xx + g * yy + p)
    x = 0.5 + x + 0.05 * rng.standard_normal(x.shape)
    y = np.roll(x, int(rng.integers(-2, 3)), axis=1) * rng.uniform(0.9, 1.1)
    y += rng.uniform(0.01, 0.1) * rng.standard_normal(y.shape)
    for img in (x, y):  # flat patches (where SSIM's cancellation is worst)
        i, j = int(rng.integers(0, h - 12)), int(rng.integers(0, w - 12))
        img[i:i + 12, j:j + 12] = rng.uniform(0.2, 0.8)
    return {"x": np.clip(x, 0, 1).astype(np.float32), "y": np.clip(y, 0, 1).astype(np.float32)}


def _window(kind, sigma):
    t = np.arange(11) - 5.0
    k = np.ones(11) if kind == "box" else np.exp(-t * t / (2 * sigma * sigma))
    return k / k.sum()


def _blur(img, k, padding):
    """Separable 11-tap filter of (H, W) ``img`` under ``padding`` ("zero", "reflect"
    or "valid")."""
    r = 5
    if padding == "valid":
        a = img
    else:
        a = np.pad(img, r, mode="constant" if padding == "zero" else "reflect")
    h, w = a.shape
    rows = sum(k[i] * a[i:h - 2 * r + i, :] for i in range(11))
    return sum(k[i] * rows[:, i:w - 2 * r + i] for i in range(11))


LOSS_MISTAKES = (
    StageMistake("data_range_255", "C1, C2 for a data range of 255 on [0, 1] images"),
    StageMistake("unsquared_constants", "C1, C2 not squared (0.01 and 0.03 instead of 0.01² "
                 "and 0.03²)"),
    StageMistake("box_window", "an 11×11 box window instead of the Gaussian"),
    StageMistake("sigma_1", "a Gaussian window of σ = 1 instead of 1.5"),
    StageMistake("sample_covariance", "sample (N/(N−1)) instead of population moments"),
    StageMistake("grayscale", "SSIM of the channel mean instead of per channel"),
    StageMistake("no_dssim", "SSIM added instead of 1 − SSIM (the loss only)"),
)


def _constants(mistake):
    """SSIM's C1, C2 under a hypothesis: ``(0.01·L)², (0.03·L)²`` for a data range L = 1."""
    return {"data_range_255": (2.55 ** 2, 7.65 ** 2),
            "unsquared_constants": (0.01, 0.03)}.get(mistake, (0.01 ** 2, 0.03 ** 2))


def _setup(x, y, conventions, mistake):
    """The images (grey for ``grayscale``), window, constants, padding and covariance
    factor of a hypothesis."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if mistake == "grayscale":
        x, y = x.mean(axis=2, keepdims=True), y.mean(axis=2, keepdims=True)
    k = _window("box" if mistake == "box_window" else "gaussian",
                1.0 if mistake == "sigma_1" else 1.5)
    # The weighted unbiased moments: 1 / (1 − Σw²).
    f = 1.0 / (1.0 - (np.outer(k, k) ** 2).sum()) if mistake == "sample_covariance" else 1.0
    padding = {"inria": "zero", "valid": "valid", "reflect": "reflect"}[conventions]
    return x, y, k, _constants(mistake), padding, f


def _terms(a, b, k, c, padding, f):
    """SSIM's map of one channel and its partial derivatives with respect to the local
    moments E[x], E[x²], E[xy] (zero padding only needs them)."""
    c1, c2 = c
    blur = lambda v: _blur(v, k, padding)  # noqa: E731
    mx, my = blur(a), blur(b)
    sxx, syy, sxy = ((blur(a * a) - mx * mx) * f, (blur(b * b) - my * my) * f,
                     (blur(a * b) - mx * my) * f)
    a1, a2 = 2 * mx * my + c1, 2 * sxy + c2
    b1, b2 = mx * mx + my * my + c1, sxx + syy + c2
    s = (a1 * a2) / (b1 * b2)
    d_mx = 2 * my * a2 / (b1 * b2) - 2 * mx * s / b1
    d_sxx, d_sxy = -s / b2, 2 * a1 / (b1 * b2)
    # Through sxx = f·(E[x²] − mx²) and sxy = f·(E[xy] − mx·my).
    return s, (d_mx - f * (2 * mx * d_sxx + my * d_sxy), f * d_sxx, f * d_sxy)


def ssim_map_reference(x, y, *, conventions="inria", mistake=None):
    """SSIM's per-pixel map in float64 (the mean over channels, ``(H, W)``, or
    ``(H − 10, W − 10)`` for "valid") under ``conventions``, optionally with one of
    ``LOSS_MISTAKES`` (by name)."""
    x, y, k, c, padding, f = _setup(x, y, conventions, mistake)
    return np.mean([_terms(x[..., i], y[..., i], k, c, padding, f)[0]
                    for i in range(x.shape[2])], axis=0)


def ssim_reference(x, y, *, conventions="inria", mistake=None):
    """Mean SSIM in float64 under ``conventions`` ("inria", "valid", "reflect"), optionally
    with one of ``LOSS_MISTAKES`` (by name)."""
    return float(np.mean(ssim_map_reference(x, y, conventions=conventions, mistake=mistake)))


def loss_gradient_reference(x, y, *, mistake=None):
    """The gradient of INRIA's loss ``0.8·L1 + 0.2·(1 − SSIM)`` (zero padding) with respect
    to ``x`` in float64, ``(H, W, C)``, optionally with one of ``LOSS_MISTAKES``: the
    adjoint of the blur of a symmetric window under zero padding is the same blur, so
    dSSIM/dx = (K∗g₁ + 2x·K∗g₂ + y·K∗g₃) / N with g the derivatives by E[x], E[x²], E[xy]."""
    x0 = np.asarray(x, np.float64)
    a, b, k, c, _, f = _setup(x, y, "inria", mistake)
    n = a.size
    grad = np.empty(a.shape)
    for i in range(a.shape[2]):
        _, (g1, g2, g3) = _terms(a[..., i], b[..., i], k, c, "zero", f)
        blur = lambda v: _blur(v, k, "zero")  # noqa: E731
        grad[..., i] = (blur(g1) + 2 * a[..., i] * blur(g2) + b[..., i] * blur(g3)) / n
    if mistake == "grayscale":  # the channel mean spreads a third to each channel
        grad = np.repeat(grad / x0.shape[2], x0.shape[2], axis=2)
    dssim = grad if mistake == "no_dssim" else -grad
    y0 = np.asarray(y, np.float64)
    return (1 - LAMBDA_DSSIM) * np.sign(x0 - y0) / x0.size + LAMBDA_DSSIM * dssim
