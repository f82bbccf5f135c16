"""Densification for ports: ``compare_densify``'s cases and known mistakes (SPEC.md §14.3).

One densify-and-prune step decides, per Gaussian, clone / split / keep and, per Gaussian
after the growth, prune; then it lays the new scene out in a fixed order (kept originals,
clones, the first children, the second children, each in index order). A Gaussian within
float noise of a threshold (its mean gradient, its largest scale, its opacity, the
large-Gaussian test) may be decided either way by a port and is set aside with
everything it becomes. To know what each of a port's rows became, every case tags each
Gaussian in its last SH coefficient (every port copies SH unchanged); split children get
the case's normal draws (``normals[c, i]`` for copy ``c`` of Gaussian ``i``), so their
means are comparable number for number.
"""

import numpy as np

from ._stage import StageMistake

#: Values within this share of a threshold are within a port's float noise of it: the
#: mean gradient is one float32 division (≤ 1 ulp), a scale one ``exp`` (the oracle's own,
#: ≤ 2 ulps from a correctly rounded one), the opacity one sigmoid; ×4 for the other side.
DECISION_REL = 1e-6
#: A child's log scale may differ by this much: ``ln(s / 1.6)`` against ``ln s − ln 1.6``
#: (a few ulps of values up to ≈ 10, the constant rounded either way).
CHILD_SCALE_ATOL = 4e-6
#: A child's mean may differ by this share of ``|mean| + Σ|R|·s·|z|`` (its float32
#: product and sum in any order: ≈ 4 roundings, ×4).
CHILD_MEAN_REL = 1e-6
#: At most this share of a case's Gaussians may be set aside.
MAX_SET_ASIDE = 0.05


def densify_case(seed):
    """A seeded case: a scene of 150–300 Gaussians (``means``, ``quats`` (wxyz, not
    normalised), ``scales`` (log), ``opacities`` (logits), ``sh`` (N, K, 3), K = 4, 9 or
    16, the last coefficient's blue channel the Gaussian's index) around a scene of
    ``extent`` 2–6, its gradient statistics (``grad_accum`` float32 and ``count`` uint32:
    0–6 views, mean gradients log-uniform over 0.1–10× the threshold), ``world_prune`` (odd
    seeds) and ``normals`` (float32 (2, N, 3)). Largest scales span 0.1–15× the clone
    limit, beyond the large-Gaussian limit; opacities 0.0005–0.99; Gaussians 0, 1 and 2
    lie on the gradient threshold, the clone limit and the prune opacity (set aside)."""
    rng = np.random.default_rng(np.random.PCG64(70_000 + seed))
    n = int(rng.integers(150, 301))
    extent = float(rng.uniform(2, 6))
    dense = 0.01 * extent
    means = rng.uniform(-extent / 2, extent / 2, (n, 3))
    largest = dense * 10 ** rng.uniform(-1, np.log10(15), n)
    scales = np.log(largest[:, None] * rng.uniform(0.2, 1.0, (n, 3)))
    scales[np.arange(n), rng.integers(0, 3, n)] = np.log(largest)
    quats = rng.normal(size=(n, 4)) * rng.uniform(0.5, 2.0, (n, 1))
    opacity = rng.uniform(0.001, 0.99, n)
    low = rng.random(n) < 0.15
    opacity[low] = rng.uniform(0.0005, 0.01, int(low.sum()))
    k = (4, 9, 16)[seed % 3]
    sh = rng.normal(0, 0.3, (n, k, 3))
    sh[:, -1, 2] = np.arange(n)
    count = rng.integers(0, 7, n).astype(np.uint32)
    mean_grad = 2e-4 * 10 ** rng.uniform(-1, 1, n)
    grad_accum = (mean_grad * count).astype(np.float32)
    # Three Gaussians on a threshold: the mean gradient (INRIA clones at ≥, gsplat at >),
    # the clone limit and the prune opacity.
    count[0], grad_accum[0] = 1, np.float32(2e-4)
    scales[1] = np.log(dense)
    opacity[2] = 0.005
    return {
        "means": means.astype(np.float32), "quats": quats.astype(np.float32),
        "scales": scales.astype(np.float32),
        "opacities": np.log(opacity / (1 - opacity)).astype(np.float32),
        "sh": sh.astype(np.float32), "grad_accum": grad_accum, "count": count,
        "extent": extent, "world_prune": bool(seed % 2),
        "normals": rng.standard_normal((2, n, 3)).astype(np.float32),
    }


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-np.asarray(x, np.float64)))


#: The step's thresholds (INRIA's; gsplat's ``DefaultStrategy`` defaults): the mean
#: gradient that makes a Gaussian grow (``grow_grad2d``), the largest scale up to which it
#: is cloned rather than split and the one beyond which it is pruned as too large, both as
#: shares of the extent (``grow_scale3d``, ``prune_scale3d``, times gsplat's
#: ``scene_scale``), and the opacity below which it is pruned (``prune_opa``).
THRESHOLDS = {"grad_threshold": 2e-4, "percent_dense": 0.01, "min_opacity": 0.005,
              "world_prune_fraction": 0.1}
#: What each threshold is called in a report.
THRESHOLD_TEXT = {
    "grad_threshold": "a gradient threshold (grow_grad2d)",
    "percent_dense": "a clone / split limit (grow_scale3d, or a scene_scale) of the extent",
    "min_opacity": "a prune opacity (prune_opa)",
    "world_prune_fraction": "a large-Gaussian limit (prune_scale3d) of the extent",
}


def near_decisions(case, thresholds=None):
    """Per Gaussian of the case, whether a threshold decision about it or what it becomes
    lies within ``DECISION_REL`` of the threshold (bool ``(N,)``)."""
    t = {**THRESHOLDS, **(thresholds or {})}
    count = case["count"].astype(np.float32)
    grad = np.where(count > 0, case["grad_accum"] / np.maximum(count, 1), 0).astype(np.float64)
    largest = np.exp(case["scales"].astype(np.float64).max(1))
    extent = case["extent"]

    def near(x, limit):
        return np.abs(x - limit) <= DECISION_REL * abs(limit)

    flags = near(grad, t["grad_threshold"]) | near(largest, t["percent_dense"] * extent)
    flags |= near(_sigmoid(case["opacities"]), t["min_opacity"])
    if case["world_prune"]:
        big = t["world_prune_fraction"] * extent
        flags |= near(largest, big) | near(largest / 1.6, big)
    return flags


def parse_rows(out, case):
    """What each row of a densified scene is: ``(origin, kind)`` with kind ``"copy"`` (the
    original's parameters, bit for bit) or ``"child"`` (its log scales shrunk by ln 1.6,
    within ``CHILD_SCALE_ATOL``), or ``(origin, "unknown")``; origin −1 for a row whose tag
    names no Gaussian."""
    n = len(case["means"])
    tags = np.asarray(out["sh"])[:, -1, 2]
    rows = []
    for r, tag in enumerate(tags):
        i = int(tag) if float(tag).is_integer() and 0 <= tag < n else -1
        if i < 0:
            rows.append((-1, "unknown"))
            continue
        s = np.asarray(out["scales"][r])
        if s.tobytes() == case["scales"][i].tobytes():
            rows.append((i, "copy"))
        elif np.all(np.abs(s.astype(np.float64) - (case["scales"][i] - np.log(1.6)))
                    <= CHILD_SCALE_ATOL):
            rows.append((i, "child"))
        else:
            rows.append((i, "unknown"))
    return rows


DENSIFY_MISTAKES = (
    StageMistake("sum_not_mean", "the summed gradient, not its mean over the views"),
    StageMistake("keep_split_originals", "split Gaussians kept beside their children"),
    StageMistake("no_shrink", "children at their parent's scale (not divided by 1.6)"),
    StageMistake("prune_originals_only", "the prune tested on the original Gaussians only, "
                 "not on the clones and children"),
    StageMistake("interleaved_children", "children interleaved per Gaussian (i₀ c₀, i₀ c₁, …), "
                 "not block by block"),
    StageMistake("no_size_test", "every hot Gaussian split, none cloned (no size test)"),
)


#: Mistakes in the children's values, which keep every decision and the layout: judged
#: child by child (``_child_and_copy_values``) and named from there.
DENSIFY_VALUE_MISTAKES = (
    StageMistake("twin_children", "both children of a split Gaussian drawn from one normal "
                 "draw (twins at one point: identical gradients, they never separate)"),
    StageMistake("swapped_draws", "copy c of a split Gaussian drawn from normals[1 − c], "
                 "not normals[c]"),
    StageMistake("revised_opacity", "split children at the revised opacity 1 − √(1 − α) "
                 "(gsplat's revised_opacity, arXiv:2404.06109), not their parent's"),
)


def densify_reference(case, mistake=None, thresholds=None):
    """A NumPy densify-and-prune step of ``case`` (float32 values, float64 decisions)
    under ``mistake`` (one of ``DENSIFY_MISTAKES``' or ``DENSIFY_VALUE_MISTAKES``' names, or
    None) and ``thresholds`` (``THRESHOLDS``' keys; the others at their value): the new
    scene's arrays."""
    t = {**THRESHOLDS, **(thresholds or {})}
    n = len(case["means"])
    count = case["count"].astype(np.float32)
    grad = np.where(count > 0, case["grad_accum"] / np.maximum(count, np.float32(1)),
                    np.float32(0))
    if mistake == "sum_not_mean":
        grad = case["grad_accum"]
    extent = np.float32(case["extent"])
    hot = grad >= np.float32(t["grad_threshold"])
    largest = np.exp(case["scales"].max(1))
    small = largest <= np.float32(t["percent_dense"]) * extent
    clone = np.nonzero(hot & small)[0]
    split = np.nonzero(hot & ~small)[0]
    if mistake == "no_size_test":
        clone, split = clone[:0], np.nonzero(hot)[0]
    keys = ("means", "quats", "scales", "opacities", "sh")
    orig = {k: case[k] for k in keys}
    q = case["quats"][split].astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    rot = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
                   1).reshape(-1, 3, 3)
    s = np.exp(case["scales"][split].astype(np.float64))
    opacity = case["opacities"][split]
    if mistake == "revised_opacity":
        a = 1 - np.sqrt(1 - _sigmoid(opacity))
        opacity = np.log(a / (1 - a)).astype(np.float32)
    blocks = []
    for c in range(2):
        draw = {"twin_children": 0, "swapped_draws": 1 - c}.get(mistake, c)
        zc = case["normals"][draw, split].astype(np.float64)
        means = (np.einsum("nij,nj->ni", rot, s * zc) + case["means"][split]).astype(np.float32)
        shrink = 0.0 if mistake == "no_shrink" else np.log(1.6)
        block = {k: orig[k][split] for k in keys}
        block["means"] = means
        block["scales"] = (case["scales"][split] - shrink).astype(np.float32)
        block["opacities"] = opacity
        blocks.append(block)
    if mistake == "interleaved_children":
        children = {k: np.stack([blocks[0][k], blocks[1][k]], 1).reshape(
            -1, *orig[k].shape[1:]) for k in keys}
    else:
        children = {k: np.concatenate([blocks[0][k], blocks[1][k]]) for k in keys}
    grown = {k: np.concatenate([orig[k], orig[k][clone], children[k]]) for k in keys}
    m = len(grown["means"])
    remove = np.zeros(m, bool)
    if mistake != "keep_split_originals":
        remove[split] = True
    tested = np.arange(m) < (n if mistake == "prune_originals_only" else m)
    transparent = _sigmoid(grown["opacities"]) < t["min_opacity"]
    big = (np.exp(grown["scales"].max(1)) > t["world_prune_fraction"] * extent
           if case["world_prune"] else False)
    remove |= tested & (transparent | big)
    return {k: v[~remove] for k, v in grown.items()}


def _interval(below, above):
    """The thresholds ``t`` with every value of ``below`` under it and every value of
    ``above`` at or over it: ``(lo, hi)``, or None when there is none."""
    lo = float(np.max(below)) if len(below) else 0.0
    hi = float(np.min(above)) if len(above) else np.inf
    return (lo, hi) if lo < hi else None


def inferred_thresholds(case, rows, flags):
    """The thresholds a port's decisions imply: for each of ``THRESHOLDS``' keys the
    interval ``(lo, hi)`` every threshold consistent with what the port's rows (``rows``,
    ``parse_rows``) made of the Gaussians lies in, or None when no single threshold
    explains them. Gaussians set aside (``flags``) do not count; the opacity is read from
    Gaussians well inside the large-Gaussian limit, that limit from opaque ones (α ≥ 0.05,
    10× the prune opacity)."""
    n = len(flags)
    copies, children = np.zeros(n, np.int64), np.zeros(n, np.int64)
    for i, kind in rows:
        if i >= 0 and kind == "copy":
            copies[i] += 1
        elif i >= 0 and kind == "child":
            children[i] += 1
    count = case["count"].astype(np.float64)
    grad = np.where(count > 0, case["grad_accum"] / np.maximum(count, 1), 0.0)
    largest = np.exp(case["scales"].astype(np.float64).max(1)) / case["extent"]
    alpha = _sigmoid(case["opacities"])
    ok = ~flags
    grown, stayed = ok & ((copies >= 2) | (children >= 1)), ok & (copies == 1) & (children == 0)
    cloned, split = ok & (copies >= 2), ok & (children >= 1) & (copies == 0)
    gone = ok & (copies == 0) & (children == 0)
    out = {"grad_threshold": _interval(grad[stayed], grad[grown]),
           "percent_dense": _interval(largest[cloned], largest[split])}
    # A split Gaussian's rows are its children, 1.6 times smaller.
    row_largest = np.where(split, largest / 1.6, largest)
    thin = row_largest <= THRESHOLDS["world_prune_fraction"] / 2 if case["world_prune"] else ok
    out["min_opacity"] = _interval(alpha[gone & thin], alpha[ok & thin & ~gone])
    opaque = alpha >= 10 * THRESHOLDS["min_opacity"]
    out["world_prune_fraction"] = _interval(
        row_largest[ok & opaque & ~gone], row_largest[gone & opaque]
    ) if case["world_prune"] else (0.0, np.inf)
    return out


def threshold_hypotheses(case, rows, flags):
    """``(text, thresholds)`` for each threshold (or, with the large-Gaussian prune on, the
    extent both size limits scale with: gsplat's ``scene_scale``) whose interval implied
    by the port's decisions (``inferred_thresholds``) excludes the oracle's value; the
    hypothesis uses the interval's geometric middle."""
    out = []
    inferred = inferred_thresholds(case, rows, flags)

    def middle(lo, hi):
        if lo <= 0:
            return hi / 1.5
        return lo * 1.5 if not np.isfinite(hi) else float(np.sqrt(lo * hi))

    def span(lo, hi):
        return f"≥ {lo:.3g}" if not np.isfinite(hi) else (
            f"≤ {hi:.3g}" if lo <= 0 else f"{lo:.3g}–{hi:.3g}")

    for key, value in THRESHOLDS.items():
        iv = inferred[key]
        if iv is None or iv[0] < value <= iv[1]:
            continue
        if key == "world_prune_fraction" and not case["world_prune"]:
            continue
        out.append((f"{THRESHOLD_TEXT[key]} of {span(*iv)}, not {value:g}",
                    {key: middle(*iv)}))
    size, big = inferred["percent_dense"], inferred["world_prune_fraction"]
    if case["world_prune"] and size is not None and big is not None:
        # One factor k on both limits: k·0.01 in the size interval, k·0.1 in the other.
        lo = max(size[0] / THRESHOLDS["percent_dense"], big[0] / THRESHOLDS["world_prune_fraction"])
        hi = min(size[1] / THRESHOLDS["percent_dense"], big[1] / THRESHOLDS["world_prune_fraction"])
        if lo < hi and not lo < 1.0 <= hi:
            k = middle(lo, hi)
            out.append((f"an extent (scene_scale) of {span(lo, hi)} times the scene's, "
                        "scaling both size limits",
                        {"percent_dense": k * THRESHOLDS["percent_dense"],
                         "world_prune_fraction": k * THRESHOLDS["world_prune_fraction"]}))
    return out


def row_differences(rows_a, rows_b, flags):
    """How two densified scenes' rows differ, set-aside Gaussians dropped: the Gaussians
    whose copies and children differ in number, and the positions at which the two row
    sequences of the other Gaussians differ: ``(decisions, order, first)``, ``first`` a
    Gaussian that differs (or None)."""
    n = len(flags)

    def counts(rows):
        c = np.zeros((n, 2), np.int64)
        for i, kind in rows:
            if i >= 0 and kind != "unknown":
                c[i, int(kind == "child")] += 1
        return c

    ca, cb = counts(rows_a), counts(rows_b)
    mismatch = np.any(ca != cb, axis=1)
    differ = np.nonzero(mismatch & ~flags)[0]
    skip = flags | mismatch
    seq_a = [r for r in rows_a if r[0] >= 0 and not skip[r[0]]]
    seq_b = [r for r in rows_b if r[0] >= 0 and not skip[r[0]]]
    moved = sum(a != b for a, b in zip(seq_a, seq_b))
    first = int(differ[0]) if len(differ) else next(
        (a[0] for a, b in zip(seq_a, seq_b) if a != b), None)
    return len(differ), moved, first


# -- Adam's moments through a densification step ------------------------------------------

#: Ways a port carries the optimizer's moments through the step wrongly. The convention
#: (INRIA's `cat_tensors_to_optimizer` and `_prune_optimizer`, gsplat's strategy ops): a
#: Gaussian that stays keeps its moments, every new row (a clone's copy, a split child)
#: starts from zero, a removed one takes its moments with it.
MOMENT_MISTAKES = (
    StageMistake("parent_moments", "the new Gaussians (clones, split children) take their "
                 "parent's Adam moments, not zeros"),
    StageMistake("reset_moments", "every Adam moment reset to zero (a new optimizer after "
                 "densifying)"),
    StageMistake("unmoved_moments", "the moments left in the input's row order, not selected "
                 "and appended with the Gaussians"),
)

_KEYS = ("means", "quats", "scales", "opacities", "sh")


def densify_moments(case, seed):
    """Adam moments for ``case``: ``(exp_avg, exp_avg_sq)``, each a dict of float32 arrays
    shaped like the scene's (second moments positive), from their own stream (the case's
    draws are unchanged)."""
    rng = np.random.default_rng(np.random.PCG64(71_000 + seed))
    m = {k: rng.normal(0, 1e-3, case[k].shape).astype(np.float32) for k in _KEYS}
    v = {k: (rng.random(case[k].shape) * 1e-6 + 1e-12).astype(np.float32) for k in _KEYS}
    return m, v


def expected_moments(name, rows, moments, n_in):
    """The moments of the output rows ``rows`` (``parse_rows`` of the oracle's layout) that
    ``name`` (``"none"``: the convention, or one of ``MOMENT_MISTAKES``) carries from the
    input ``moments`` (a dict per key)."""
    out = {}
    for k, a in moments.items():
        o = np.zeros((len(rows),) + a.shape[1:], a.dtype)
        seen = set()
        for r, (i, kind) in enumerate(rows):
            stays = kind == "copy" and i not in seen
            if kind == "copy":
                seen.add(i)
            if name == "none" and stays and i >= 0:
                o[r] = a[i]
            elif name == "parent_moments" and i >= 0:
                o[r] = a[i]
            elif name == "unmoved_moments" and r < n_in:
                o[r] = a[r]
        out[k] = o
    return out
