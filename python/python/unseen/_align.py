"""Depth alignment for ports: ``compare_align``'s cases and known mistakes (SPEC.md §17).

The pipeline fits ``s·r + t ≈ m`` (``m`` the metric depth or disparity) by RANSAC with an
inlier threshold relative to ``|m|``. A port's RANSAC draws other samples, so its scale and
offset cannot be compared with the oracle's number for number; it is judged by what the
fit is for: its consensus (pixels within the threshold, under the oracle's rule) may fall
short of the oracle's by ``CONSENSUS_SLACK``, and its mean relative residual over those
pixels may exceed the oracle's by ``RESIDUAL_SLACK``. Least squares is deterministic and
compared number for number (``LSQ_RTOL``).
"""

import numpy as np

from ._stage import StageMistake

#: A port's consensus may be this share below the oracle's: two RANSACs with a final
#: least-squares refit on their inliers land on the same structure, and differ by the
#: pixels within float noise of the threshold and those the refits trade (measured:
#: scikit-learn's RANSACRegressor within 0.2 % on 20 seeds).
CONSENSUS_SLACK = 0.01
#: A port's mean relative residual over its consensus may be this share above the oracle's.
RESIDUAL_SLACK = 0.05
#: Least squares, float64 against float64 (centred sums against a port's own): relative.
LSQ_RTOL = 1e-9


def _target(depth, space):
    d = np.asarray(depth, np.float64)
    return d if space == "depth" else 1.0 / d


def _valid(estimate, depth):
    r, d = np.asarray(estimate, np.float64), np.asarray(depth, np.float64)
    return np.isfinite(r) & np.isfinite(d) & (d > 0)


def consensus(scale, offset, estimate, depth, *, space, threshold):
    """The pixels the model ``scale·r + offset`` fits within ``threshold·|m|`` (SPEC.md §17's
    rule) and their mean relative residual: ``(count, mean)``."""
    ok = _valid(estimate, depth)
    r = np.asarray(estimate, np.float64)[ok]
    m = _target(np.asarray(depth)[ok], space)
    rel = np.abs(scale * r + offset - m) / np.abs(m)
    inl = rel <= threshold
    return int(inl.sum()), float(rel[inl].mean()) if inl.any() else np.inf


def align_case(seed):
    """A seeded case: ``estimate`` and ``depth`` (float32 (3000,)), ``space``, ``threshold``
    and ``method``. Depths 0.5–6 m; the estimate is the target under a random scale and
    offset with 1 % noise, 10–40 % outliers (uniform over the estimate's range, but those
    among the smallest third of ``|m|`` a second surface 12–20 % of ``m`` off the line: what
    an absolute threshold cannot tell from the line where ``|m|`` is small), 3 %
    pixels without depth and 1 % without estimate; space alternates between disparity and
    depth; every fourth case is least squares."""
    rng = np.random.default_rng(np.random.PCG64(20_000 + seed))
    n = 3000
    space = ("disparity", "depth")[seed % 2]
    method = "least_squares" if seed % 4 == 3 else "ransac"
    d = rng.uniform(0.5, 6.0, n)
    s0, t0 = 10 ** rng.uniform(-0.7, 0.7), rng.uniform(-0.2, 0.2)
    m = _target(d, space)
    r = (m - t0) / s0 * (1 + 0.01 * rng.standard_normal(n))
    if method == "ransac":
        out = rng.random(n) < rng.uniform(0.1, 0.4)
        r[out] = rng.uniform(r.min(), r.max(), out.sum())
        # The outliers among the smallest third of |m| (the far wall in disparity, the
        # near object in depth) form a second surface, 12–20 % of m off the line: beyond
        # twice the relative threshold (no line holds both), but inside an absolute one
        # where |m| is small, so an absolute rule lets it bend the fit. Its draws have
        # their own stream: the case's others are those of the generator without it.
        own = np.random.default_rng(np.random.PCG64(25_000 + seed))
        small = (np.abs(m) <= np.quantile(np.abs(m), 0.35)) & out
        off = own.uniform(0.12, 0.2) * own.choice([-1, 1])
        r[small] = (m[small] * (1 + off) - t0) / s0 * (
            1 + 0.005 * own.standard_normal(int(small.sum())))
    d[rng.random(n) < 0.03] = 0.0
    r[rng.random(n) < 0.01] = np.nan
    return {"estimate": r.astype(np.float32), "depth": d.astype(np.float32), "space": space,
            "threshold": 0.05, "method": method}


ALIGN_MISTAKES = (
    StageMistake("wrong_space", "the fit in the other space (depth for disparity or back)"),
    StageMistake("no_offset", "no offset (s·r ≈ m through the origin)"),
    StageMistake("no_ransac", "least squares over every pixel (outliers included)"),
    StageMistake("swapped", "estimate and target swapped (r fitted to m)"),
    StageMistake("absolute_threshold", "an absolute inlier threshold |s·r + t − m| ≤ "
                 "threshold (scikit-learn's default loss), not relative to |m|"),
)


def _lsq(x, y):
    mx, my = x.mean(), y.mean()
    s = ((x - mx) * (y - my)).sum() / ((x - mx) ** 2).sum()
    return s, my - s * mx


def _ransac(x, y, inlier, seed, iterations=1000):
    rng = np.random.default_rng(np.random.PCG64(seed))
    best = (-1, 0.0, 0.0)
    for _ in range(iterations):
        i, j = rng.integers(len(x), size=2)
        if x[i] == x[j]:
            continue
        s = (y[j] - y[i]) / (x[j] - x[i])
        t = y[i] - s * x[i]
        c = int(inlier(s, t).sum())
        if c > best[0]:
            best = (c, s, t)
    keep = inlier(best[1], best[2])
    return _lsq(x[keep], y[keep])


def mistaken_consensus(name, scale, offset, estimate, depth, *, space, threshold):
    """The consensus count of the fit ``(scale, offset)`` under mistake ``name``'s own model
    and rule (``wrong_space``: in the other space; ``swapped``: ``scale·m + offset ≈ r``
    within ``threshold·|r|``; ``no_offset``: through the origin, 0 for a fit with an
    offset; ``absolute_threshold``: within ``threshold``), or None for a mistake without a
    consensus (``no_ransac``). A port that made the mistake with its own RANSAC draws holds
    as much consensus under that rule as the mistake's emulation does, whatever its
    draws."""
    ok = _valid(estimate, depth)
    r = np.asarray(estimate, np.float64)[ok]
    m = _target(np.asarray(depth)[ok], space)
    if name == "wrong_space":
        m = _target(np.asarray(depth)[ok], "depth" if space == "disparity" else "disparity")
    elif name == "swapped":
        r, m = m, r
    elif name == "no_offset":
        if offset != 0.0:
            return 0
    elif name == "absolute_threshold":
        return int((np.abs(scale * r + offset - m) <= threshold).sum())
    else:
        return None
    return int((np.abs(scale * r + offset - m) <= threshold * np.abs(m)).sum())


def mistaken_fit(name, estimate, depth, *, space, threshold, seed=0):
    """The ``(scale, offset)`` mistake ``name`` fits (float64, its own seeded RANSAC)."""
    ok = _valid(estimate, depth)
    r = np.asarray(estimate, np.float64)[ok]
    m = _target(np.asarray(depth)[ok], space)
    if name == "no_ransac":
        return _lsq(r, m)
    if name == "wrong_space":
        m = _target(np.asarray(depth)[ok], "depth" if space == "disparity" else "disparity")
    if name == "swapped":
        return _ransac(m, r, lambda s, t: np.abs(s * m + t - r) <= threshold * np.abs(r), seed)
    if name == "absolute_threshold":
        return _ransac(r, m, lambda s, t: np.abs(s * r + t - m) <= threshold, seed)
    if name == "no_offset":
        s, t = _ransac(r, m, lambda s, t: np.abs(s * r + t - m) <= threshold * np.abs(m), seed)
        keep = np.abs(s * r + t - m) <= threshold * np.abs(m)
        return float((r[keep] * m[keep]).sum() / (r[keep] ** 2).sum()), 0.0
    return _ransac(r, m, lambda s, t: np.abs(s * r + t - m) <= threshold * np.abs(m), seed)
