"""Adam through unseen.testing (SPEC.md §14.2): the oracle, a float32 port written from the
update, eight seeded wrong ports (each must fail with its mistake named) and the real
third-party optimizer, ``torch.optim.Adam`` as INRIA's code trains with it (its default
for-loop kernel and its fused one), on 20 seeds of ``adam_case``. torch's test is skipped,
with the reason printed, where torch is not installed.
"""

import numpy as np
import pytest

import unseen
from unseen import testing as ut

SEEDS = range(20)
F = np.float32


def float32_port(mistake=None):
    """Adam written out in float32 numpy (PyTorch's constants: Python-float β), optionally
    with one of ``ut.ADAM_MISTAKES``: what a hand-written port computes."""

    def port(params, grads, *, lr, betas, eps):
        b1, b2 = betas[::-1] if mistake == "betas_swapped" else betas
        x, m, v = params.copy(), np.zeros_like(params), np.zeros_like(params)
        for t, g in enumerate(grads):
            n = t + 2 if mistake == "step_off_by_one" else t + 1
            m = (F(b1) * m + F(1 - b1) * g).astype(F)
            sq = np.abs(g) if mistake == "abs_not_square" else g * g
            v = (F(b2) * v + F(1 - b2) * sq).astype(F)
            c1, c2 = 1 - b1 ** n, (1 - b2 ** n) ** 0.5
            root = np.sqrt(v)
            step, denom = {
                "no_bias_correction": (F(lr), root + F(eps)),
                "no_first_correction": (F(lr), root / F(c2) + F(eps)),
                "no_second_correction": (F(lr / c1), root + F(eps)),
                "eps_inside_sqrt": (F(lr / c1), np.sqrt(v / F(c2 * c2) + F(eps))),
                "eps_hat": (F(lr * c2 / c1), root + F(eps)),
            }.get(mistake, (F(lr / c1), root / F(c2) + F(eps)))
            x = (x - step * (m / denom.astype(F))).astype(F)
        return {"params": x, "exp_avg": m, "exp_avg_sq": v}

    return port


def test_the_oracle_follows_its_constants_and_refuses_bad_input():
    g = np.array([[0.5, -2.0]], F)
    torch_like = unseen.adam(np.zeros(2, F), g, lr=0.01)
    trainer = unseen.adam(np.zeros(2, F), g, lr=0.01, conventions="unseen")
    assert torch_like["exp_avg_sq"].shape == (1, 2)
    # 1 − β2: 0.001 as PyTorch's Python float, 1 − 0.999f32 as the trainer's f32.
    np.testing.assert_array_equal(torch_like["exp_avg_sq"][0], F(0.001) * (g[0] * g[0]))
    np.testing.assert_array_equal(trainer["exp_avg_sq"][0], (F(1) - F(0.999)) * (g[0] * g[0]))
    # A first step moves every coordinate with a gradient by lr (ε aside).
    np.testing.assert_allclose(torch_like["params"][0], [-0.01, 0.01], rtol=1e-6)
    with pytest.raises(ValueError, match="grads"):
        unseen.adam(np.zeros(2, F), np.zeros((3, 4), F), lr=0.01)
    with pytest.raises(ValueError, match="params"):
        unseen.adam(np.zeros(2, np.float64), g, lr=0.01)
    with pytest.raises(ValueError, match="conventions"):
        unseen.adam(np.zeros(2, F), g, lr=0.01, conventions="keras")
    with pytest.raises(ValueError, match="lr"):
        unseen.adam(np.zeros(2, F), g, lr=float("nan"))
    with pytest.raises(ValueError, match="beta"):
        unseen.adam(np.zeros(2, F), g, lr=0.01, betas=(1.5, 0.999))


@pytest.mark.parametrize("seed", SEEDS)
def test_a_float32_port_passes(seed):
    r = ut.compare_adam(float32_port(), seed=seed)
    assert r.ok, r.message()


@pytest.mark.parametrize("mistake", [m.name for m in ut.ADAM_MISTAKES
                                     if m.name != "f32_bias_correction"])
def test_wrong_ports_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.ADAM_MISTAKES if m.name == mistake)
    for seed in range(8):
        case = ut.adam_case(seed)
        r = ut.compare_adam(float32_port(mistake), case)
        assert not r.ok, f"seed {seed}: the mistake passed"
        if mistake == "no_first_correction" and len(case["grads"]) == 1:
            # On one step it is the learning rate scaled by 1 − β1: nothing is named.
            assert r.cause == "", f"seed {seed}: {r.message()}"
        else:
            assert r.cause == text, f"seed {seed}: {r.message()}"


def test_a_scaled_learning_rate_and_the_other_profile_are_named_not_mistaken():
    def scaled(params, grads, *, lr, betas, eps):
        return float32_port()(params, grads, lr=lr * 0.2, betas=betas, eps=eps)

    def other(params, grads, *, lr, betas, eps):
        out = unseen.adam(params, grads, lr=lr, betas=betas, eps=eps, conventions="unseen")
        return {k: v[-1] for k, v in out.items()}

    mistakes = {m.text for m in ut.ADAM_MISTAKES}
    for seed in range(8):
        r = ut.compare_adam(scaled, seed=seed)
        assert not r.ok and r.cause not in mistakes, r.message()
        assert r.cause.startswith("the learning rate scaled by 0.2") or not r.cause, r.message()
        r = ut.compare_adam(other, seed=seed)
        assert r.ok or r.cause == "the other constants profile ('unseen')", r.message()


def test_a_port_that_returns_every_step_or_too_little_is_judged():
    case = ut.adam_case(5)

    def every_step(params, grads, **kw):
        return unseen.adam(params, grads, **kw)

    assert ut.compare_adam(every_step, case).ok
    r = ut.compare_adam(lambda p, g, **kw: {"params": p}, case)
    assert not r.ok and "no 'exp_avg'" in r.message(), r.message()
    r = ut.compare_adam(lambda p, g, **kw: {k: p[:3] for k in ut._ADAM_KEYS}, case)
    assert not r.ok and "shape (3,)" in r.message(), r.message()


def _torch_adam(**options):
    torch = pytest.importorskip("torch", reason="torch is not installed (python/requirements-port.txt)")

    def port(params, grads, *, lr, betas, eps):
        p = torch.nn.Parameter(torch.from_numpy(params))
        opt = torch.optim.Adam([p], lr=lr, betas=betas, eps=eps, **options)
        for g in grads:
            p.grad = torch.from_numpy(g.copy())
            opt.step()
        st = opt.state[p]
        return {"params": p.detach().numpy(), "exp_avg": st["exp_avg"].numpy(),
                "exp_avg_sq": st["exp_avg_sq"].numpy()}

    return port


@pytest.mark.parametrize("options", [{}, {"fused": True}], ids=["for-loop", "fused"])
def test_torch_adam_passes_under_its_constants(options):
    port = _torch_adam(**options)
    for seed in SEEDS:
        r = ut.compare_adam(port, seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"
    # Under the trainer's float32 constants it does not: 1 − β2 differs by 1.3e-5.
    failed = sum(not ut.compare_adam(port, seed=s, conventions="unseen").ok for s in SEEDS)
    assert failed >= len(SEEDS) // 2, failed


def test_float32_bias_corrections_fail_where_they_matter_and_are_named_or_listed():
    """Issue #70: a port computing 1 − βᵗ in float32 (β rounded to float32 first: 1 − β2 =
    0.00099998713, so the step's √(1 − β2ᵗ) is 6.4e-6 off at t = 1, shrinking with t) was
    named "the learning rate scaled by 1". It is its own mistake now. It stays within the
    bound on 6 of seeds 0–11 (the longer runs, where βᵗ's share fades); where it fails it is
    named, or — on one to three steps, where a learning rate scaled by 1 − 6.4e-6 is the
    same update to the bound — listed closest beside that control, never mistaken for
    another."""
    text = next(m.text for m in ut.ADAM_MISTAKES if m.name == "f32_bias_correction")

    def port(params, grads, *, lr, betas, eps):
        b1, b2 = F(betas[0]), F(betas[1])
        x, m, v = params.copy(), np.zeros_like(params), np.zeros_like(params)
        for t, g in enumerate(grads):
            n = F(t + 1)
            m = (b1 * m + F(1 - betas[0]) * g).astype(F)
            v = (b2 * v + F(1 - betas[1]) * g * g).astype(F)
            c1, c2 = F(1) - b1 ** n, np.sqrt(F(1) - b2 ** n)
            x = (x - F(lr) / c1 * (m / (np.sqrt(v) / c2 + F(eps)))).astype(F)
        return {"params": x, "exp_avg": m, "exp_avg_sq": v}

    failed = 0
    for seed in range(12):
        r = ut.compare_adam(port, seed=seed)
        if r.ok:
            continue
        failed += 1
        msg = r.message()
        assert r.cause == text or (r.cause == "" and text in msg), f"seed {seed}: {msg}"
        assert "scaled by 1 (" not in msg, msg
    assert failed >= 5
