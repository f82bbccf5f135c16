"""Depth alignment through unseen.testing (SPEC.md §17): the oracle's binding, five seeded
wrong ports (each must fail, and be named on nearly every seed) and a real third-party
one, scikit-learn's RANSACRegressor (with the relative residual as its loss) and
LinearRegression, on 20 seeds of ``align_case``. scikit-learn's test is skipped, with the
reason printed, where it is not installed (python/requirements-stages.txt).
"""

import numpy as np
import pytest

import unseen
from unseen import testing as ut

SEEDS = range(20)


def test_the_oracle_binding_fits_and_refuses_bad_input():
    d = np.linspace(1.0, 4.0, 50, dtype=np.float32)
    r = ((1.0 / d - 0.1) / 2.0).astype(np.float32)
    fit = unseen.align(r, d, space="disparity", method="least_squares")
    assert abs(fit["scale"] - 2.0) < 1e-5 and abs(fit["offset"] - 0.1) < 1e-6
    assert fit["valid"] == 50 == fit["inliers"]
    assert unseen.align(r, d, seed=3)["inliers"] == 50
    with pytest.raises(ValueError, match="space"):
        unseen.align(r, d, space="log")
    with pytest.raises(ValueError, match="method"):
        unseen.align(r, d, method="irls")
    with pytest.raises(ValueError, match="depth: expected"):
        unseen.align(r, d[:10].copy())
    with pytest.raises(ValueError, match="at least 2 valid pixels"):
        unseen.align(r, np.zeros_like(d))


def test_the_oracle_passes_itself():
    def port(estimate, depth, *, space, threshold, method):
        f = unseen.align(estimate, depth, space=space, threshold=threshold, method=method,
                         seed=7)
        return f["scale"], f["offset"]

    for seed in range(8):
        r = ut.compare_align(port, seed=seed)
        assert r.ok, r.message()


@pytest.mark.parametrize("mistake", [m.name for m in ut.ALIGN_MISTAKES])
def test_wrong_ports_fail_with_their_mistake_named(mistake):
    text = next(m.text for m in ut.ALIGN_MISTAKES if m.name == mistake)

    def port(estimate, depth, *, space, threshold, method):
        return ut.mistaken_fit(mistake, estimate, depth, space=space, threshold=threshold,
                               seed=99)

    judged, named = _judge(port, mistake, text)
    # Measured (seeds 0–11): named on 11–12 of 12 (9 of 9 for no_ransac, 6 of 6 for the
    # absolute threshold); the rest unnamed, never another.
    assert named >= judged - 1, f"named on {named} of {judged}"


def _judge(port, mistake, text, seeds=range(12)):
    """Run ``port`` (which makes ``mistake``) on ``seeds``: each judged case must fail and
    name the mistake or none; ``(judged, named)``. A RANSAC mistake is not judged on least
    squares cases; an absolute threshold not on depth cases, where 0.05 is stricter than
    the relative rule beyond 1 m and the fit holds as much consensus (it passes there,
    rightly: 4 of 6 seeds)."""
    judged, named = 0, 0
    for seed in seeds:
        case = ut.align_case(seed)
        ransac_only = mistake in ("no_ransac", "absolute_threshold")
        if ransac_only and case["method"] == "least_squares":
            continue
        r = ut.compare_align(port, case)
        if mistake == "absolute_threshold" and case["space"] == "depth":
            assert r.cause in ("", text), f"seed {seed}: another mistake named: {r.message()}"
            continue
        assert not r.ok, f"seed {seed}: the mistake passed"
        judged += 1
        named += r.cause == text
        assert r.cause in ("", text), f"seed {seed}: another mistake named: {r.message()}"
    return judged, named


def test_scikit_learn_passes():
    lm = pytest.importorskip("sklearn.linear_model", reason="scikit-learn is not installed "
                             "(python/requirements-stages.txt)")

    def port(estimate, depth, *, space, threshold, method):
        ok = np.isfinite(estimate) & np.isfinite(depth) & (depth > 0)
        x = estimate[ok].astype(np.float64)[:, None]
        m = depth[ok].astype(np.float64)
        m = m if space == "depth" else 1.0 / m
        if method == "least_squares":
            fit = lm.LinearRegression().fit(x, m)
            return fit.coef_[0], fit.intercept_
        fit = lm.RANSACRegressor(lm.LinearRegression(), min_samples=2,
                                 residual_threshold=threshold,
                                 loss=lambda y, yhat: np.abs(y - yhat) / np.abs(y),
                                 max_trials=1000, stop_probability=0.999,
                                 random_state=0).fit(x, m)
        return fit.estimator_.coef_[0], fit.estimator_.intercept_

    for seed in SEEDS:
        r = ut.compare_align(port, seed=seed)
        assert r.ok, f"seed {seed}: {r.message()}"


def _sklearn_port(mistake):
    # scikit-learn's fit with one mistake made the way a port would make it (not the
    # harness's emulations): the naming is tested on ports it did not write.
    lm = pytest.importorskip("sklearn.linear_model", reason="scikit-learn is not installed "
                             "(python/requirements-stages.txt)")

    def port(estimate, depth, *, space, threshold, method):
        ok = np.isfinite(estimate) & np.isfinite(depth) & (depth > 0)
        r = estimate[ok].astype(np.float64)
        d = depth[ok].astype(np.float64)
        if mistake == "wrong_space":
            space = "depth" if space == "disparity" else "disparity"
        m = d if space == "depth" else 1.0 / d
        x, y = (m, r) if mistake == "swapped" else (r, m)
        model = lm.LinearRegression(fit_intercept=mistake != "no_offset")
        if method == "least_squares" or mistake == "no_ransac":
            fit = model.fit(x[:, None], y)
        else:
            # absolute_threshold: scikit-learn's default loss, |t − p|.
            loss = {} if mistake == "absolute_threshold" else {
                "loss": lambda t, p: np.abs(t - p) / np.abs(t)}
            fit = lm.RANSACRegressor(model, min_samples=2, residual_threshold=threshold,
                                     max_trials=1000, stop_probability=0.999,
                                     random_state=5, **loss).fit(x[:, None], y).estimator_
        return float(fit.coef_[0]), float(fit.intercept_)

    return port


@pytest.mark.parametrize("mistake", [m.name for m in ut.ALIGN_MISTAKES])
def test_scikit_learn_ports_with_a_mistake_fail_with_it_named(mistake):
    text = next(m.text for m in ut.ALIGN_MISTAKES if m.name == mistake)
    port = _sklearn_port(mistake)
    judged, named = _judge(port, mistake, text)
    # Measured (seeds 0-11): named on 10 of 12 (wrong space: scikit-learn's RANSAC finds
    # other lines in the curved other space than ours, by rule and by prediction), 11 of 12
    # (no offset, swapped), 9 of 9 (no RANSAC), 6 of 6 disparity cases (the absolute
    # threshold: scikit-learn's default loss); the rest unnamed, never another.
    assert 3 * named >= 2 * judged, f"named on {named} of {judged}"
