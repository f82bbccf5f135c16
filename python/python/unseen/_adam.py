"""Adam for ports: ``compare_adam``, its case generator and its known mistakes (SPEC.md §14.2).

A port of the optimizer (``torch.optim.Adam`` as INRIA's code trains, or a hand-written
one) computes the same update in float32 in another order: PyTorch forms the first moment
with ``lerp`` and divides after multiplying by the step size, unseen multiplies and adds in
the textbook order. Neither is the exact value, so the comparison allows, per value, twice
a first-order bound on a float32 implementation's distance from the exact update along the
oracle's own trajectory (``adam_bounds``): each operation rounds once (relative ``2⁻²⁴``),
the moments carry their earlier errors scaled by β, and the parameters add up every
step's error. Adam has no discrete decision, so nothing is set aside.

A value beyond its bound fails the port, and every known mistake (``ADAM_MISTAKES``) is
then run on the same case; one is named when it explains the port's values clearly better
than every other (``NAME_MAX_LEFT``, ``NAME_MIN_RATIO``, as for the rasterizer).
"""

import numpy as np

from ._stage import StageMistake


#: Unit roundoff of float32.
U32 = 2.0 ** -24
#: Roundings a port may spend per operation of the update beyond the oracle's (a `lerp`
#: is two or three, a fused multiply-add one): the local error of each moment and of the
#: step is taken as this many unit roundoffs of the magnitudes it combines.
ROUNDINGS = 3
#: Smallest positive subnormal float32: the absolute floor of every bound.
TINY = 2.0 ** -149
#: Default Adam constants of INRIA's code (PyTorch's with ε = 1e-15).
BETAS = (0.9, 0.999)
EPS = 1e-15


def adam_bounds(params, grads, trace, *, lr, betas=BETAS, eps=EPS):
    """Per value, the bound on a float32 port's distance from the exact update (first
    order, along the oracle's trajectory ``trace``), for ``params``, ``exp_avg`` and
    ``exp_avg_sq`` after every step: a dict of ``(S, N)`` float64 arrays."""
    b1, b2 = float(np.float32(betas[0])), float(np.float32(betas[1]))
    eps = float(np.float32(eps))
    g = np.asarray(grads, np.float64)
    x = np.asarray(trace["params"], np.float64)
    m = np.asarray(trace["exp_avg"], np.float64)
    v = np.asarray(trace["exp_avg_sq"], np.float64)
    k = ROUNDINGS * U32
    em = np.zeros(g.shape[1])
    ev = np.zeros(g.shape[1])
    ex = np.zeros(g.shape[1])
    m_prev = np.zeros(g.shape[1])
    v_prev = np.zeros(g.shape[1])
    out = {"params": np.empty_like(x), "exp_avg": np.empty_like(m), "exp_avg_sq": np.empty_like(v)}
    for t in range(g.shape[0]):
        em = b1 * em + k * (b1 * np.abs(m_prev) + (1 - b1) * np.abs(g[t]) + np.abs(m[t])) + TINY
        ev = b2 * ev + k * (b2 * v_prev + (1 - b2) * g[t] ** 2 + v[t]) + TINY
        step = lr / (1.0 - b1 ** (t + 1))
        bc = np.sqrt(1.0 - b2 ** (t + 1))
        root = np.sqrt(v[t])
        denom = root / bc + eps
        # |√(v + e) − √v| ≤ min(e / (2√v), √e); the quotient and the sum round too.
        with np.errstate(divide="ignore", invalid="ignore"):
            droot = np.where(root > 0, np.minimum(ev / (2 * root), np.sqrt(ev)), np.sqrt(ev))
        ed = droot / bc + k * denom
        delta = step * np.abs(m[t]) / denom
        ed_step = step * (em + np.abs(m[t]) * ed / denom) / denom + k * delta
        ex = ex + ed_step + U32 * np.abs(x[t]) + TINY
        out["params"][t], out["exp_avg"][t], out["exp_avg_sq"][t] = ex, em, ev
        m_prev, v_prev = m[t], v[t]
    return out


ADAM_MISTAKES = (
    StageMistake("no_bias_correction", "no bias correction (step lr, denominator √v + ε)"),
    StageMistake("no_first_correction", "the first moment's bias correction missing (step lr)"),
    StageMistake("no_second_correction", "the second moment's bias correction missing (√v + ε)"),
    StageMistake("eps_inside_sqrt", "ε inside the square root (√(v̂ + ε))"),
    StageMistake("eps_hat", "ε added before the bias correction (Keras ε̂: lr·√(1−β2ᵗ)/(1−β1ᵗ) · m/(√v + ε))"),
    StageMistake("betas_swapped", "β1 and β2 swapped"),
    StageMistake("step_off_by_one", "the step count one ahead (bias corrections of t + 1)"),
    StageMistake("abs_not_square", "the second moment of |g| instead of g²"),
    StageMistake("f32_bias_correction", "the bias corrections 1 − βᵗ in float32 (β rounded "
                 "first: 1 − β2 = 0.00099998713, the step's √(1 − β2ᵗ) 6.4e-6 off at t = 1)"),
)


def adam_reference(params, grads, *, lr, betas=BETAS, eps=EPS, mistake=None,
                   conventions="pytorch"):
    """Adam in float64 from zero moments, optionally with one of ``ADAM_MISTAKES`` (by
    name): the states after every step as ``(S, N)`` float64 arrays. Under
    ``conventions="unseen"`` β are first rounded to float32, as the trainer holds them."""
    b1, b2 = float(betas[0]), float(betas[1])
    if conventions == "unseen":
        b1, b2 = float(np.float32(b1)), float(np.float32(b2))
    if mistake == "betas_swapped":
        b1, b2 = b2, b1
    eps = float(np.float32(eps))
    x = np.asarray(params, np.float64).copy()
    g = np.asarray(grads, np.float64)
    m, v = np.zeros_like(x), np.zeros_like(x)
    out = {k: np.empty(g.shape) for k in ("params", "exp_avg", "exp_avg_sq")}
    for t in range(g.shape[0]):
        n = t + 2 if mistake == "step_off_by_one" else t + 1
        m = b1 * m + (1 - b1) * g[t]
        v = b2 * v + (1 - b2) * (np.abs(g[t]) if mistake == "abs_not_square" else g[t] ** 2)
        c1, c2 = 1.0 - b1 ** n, np.sqrt(1.0 - b2 ** n)
        if mistake == "f32_bias_correction":
            f, fn = np.float32, np.float32(n)
            c1 = float(f(1) - f(b1) ** fn)
            c2 = float(np.sqrt(f(1) - f(b2) ** fn))
        if mistake == "no_bias_correction":
            step, denom = lr, np.sqrt(v) + eps
        elif mistake == "no_first_correction":
            step, denom = lr, np.sqrt(v) / c2 + eps
        elif mistake == "no_second_correction":
            step, denom = lr / c1, np.sqrt(v) + eps
        elif mistake == "eps_inside_sqrt":
            step, denom = lr / c1, np.sqrt(v / c2 ** 2 + eps)
        elif mistake == "eps_hat":
            step, denom = lr * c2 / c1, np.sqrt(v) + eps
        else:
            step, denom = lr / c1, np.sqrt(v) / c2 + eps
        x = x - step * m / denom
        out["params"][t], out["exp_avg"][t], out["exp_avg_sq"][t] = x, m, v
    return out


def adam_case(seed):
    """A seeded case: ``params`` (N,), ``grads`` (S, N) float32, ``lr``, ``betas``, ``eps``.

    Gradients span many magnitudes (normal draws scaled log-uniformly from 1e-6 to 1e2),
    with exact zeros, sign flips and a block of the size of ε (0.01 ε to 10 ε) whose
    parameters are a few steps large, so that where ε sits in the denominator shows; the step
    count cycles through 1, 3, 20 and 100; ε alternates between INRIA's 1e-15 and
    PyTorch's 1e-8; every third case takes other β.
    """
    rng = np.random.default_rng(np.random.PCG64(seed))
    n = 384
    steps = (1, 3, 20, 100)[seed % 4]
    eps = (1e-15, 1e-8)[(seed // 4) % 2]
    betas = BETAS if seed % 3 else (0.8, 0.99)
    lr = float(np.float32(10 ** rng.uniform(-4, -1)))
    scale = 10 ** rng.uniform(-6, 2, size=n)
    g = rng.standard_normal((steps, n)) * scale
    g[:, rng.random(n) < 0.1] = 0.0
    g[rng.random((steps, n)) < 0.05] = 0.0
    near = np.arange(n) >= n - 64
    g[:, near] = rng.choice([-1.0, 1.0], size=(steps, near.sum())) * eps * 10 ** rng.uniform(
        -2, 1, size=(steps, near.sum()))
    x = rng.standard_normal(n) * 10 ** rng.uniform(-3, 1, size=n)
    x[near] = rng.standard_normal(near.sum()) * lr * 10
    return {"params": x.astype(np.float32), "grads": g.astype(np.float32), "lr": lr,
            "betas": betas, "eps": eps}
