"""An independent NumPy port (tests/numpy_port.py, written from gsplat's formulas) through
unseen.testing, issue #51: the float64 port of the textbook projection and the float32 port
of the stable one (SPEC.md §5.1) pass every family, ``hard`` included, at check_port's two
sizes; the float32 textbook port passes the ordinary families and fails ``hard`` with the
ill-conditioned projection named, with the Gaussians it concerns, never "none of the known
mistakes". No torch needed.

UNSEEN_NUMPY_PORT_SEEDS sets how many seeds run (default 3, ≈ 15 s; the acceptance
measurement used 20: docs/notes/rationale.md §8.1).
"""

import os
import re

import numpy as np
import pytest

import unseen
from unseen import testing

import numpy_port

SEEDS = range(int(os.environ.get("UNSEEN_NUMPY_PORT_SEEDS", "3")))
CASES = list(enumerate(testing.CHECK_FORWARD_CASES))
ORDINARY = ("random", "near_plane", "rolled", "clamp")


def _case(seed, family, case):
    n, w, h = testing.CHECK_FORWARD_CASES[case]
    dtype = np.float32 if case % 2 == 0 else np.float64  # as check_port
    s, cam = testing.scene(n, 3, seed, width=w, height=h, family=family, dtype=dtype)
    return s, cam, testing.background_for(seed, family, case)


def _compare(port, seed, family, case):
    s, cam, bg = _case(seed, family, case)
    bound = (testing.HARD_MAX_EXCLUDED_FRACTION if family == "hard"
             else testing.MAX_EXCLUDED_FRACTION)
    return s, testing.compare_render(port, s, cam, background=bg, check=False,
                                     max_excluded_fraction=bound)


def _values_pass(report):
    """Every value and intermediate within tolerance. The one failure allowed is the
    oracle's own: a scene it sets aside more of than the bound (test_oracle_stays_within_
    its_bound_on_hard follows that separately)."""
    kinds = [f.quantity for f in report.failures]
    return kinds in ([], ["excluded pixels"])


def test_the_port_is_independent_and_exact_on_a_simple_scene():
    """A sanity check of the port itself: float64 and float32, textbook and stable, agree
    with each other to float32 rounding on an ordinary scene (they share no code with the
    oracle, so the comparisons below test the harness, not a copy of it)."""
    s, cam, bg = _case(0, "random", 1)
    outs = [numpy_port.port(dt, pr)(s, cam, background=bg)
            for dt in (np.float64, np.float32) for pr in ("textbook", "stable")]
    for o in outs[1:]:
        np.testing.assert_allclose(o["rgb"], outs[0]["rgb"], atol=2e-5)
        np.testing.assert_array_equal(o["radii"] > 0, outs[0]["radii"] > 0)
    ref = unseen.render(**s, camera=cam, background=list(bg))
    assert np.abs(outs[0]["rgb"] - ref["rgb"]).max() < 1e-4


@pytest.mark.parametrize("case", [c for c, _ in CASES])
@pytest.mark.parametrize("seed", SEEDS)
def test_float64_textbook_and_float32_stable_ports_pass_hard(seed, case):
    for port in (numpy_port.port(np.float64, "textbook"),
                 numpy_port.port(np.float32, "stable")):
        _, report = _compare(port, seed, "hard", case)
        print(f"{port.__name__} seed {seed} case {case}: set aside "
              f"{report.excluded_fraction:.2%}")
        assert _values_pass(report), report.message()


@pytest.mark.parametrize("family", ORDINARY)
@pytest.mark.parametrize("seed", SEEDS)
def test_every_port_passes_the_ordinary_families(seed, family):
    """The textbook float32 form too: there no Gaussian's condition reaches 200."""
    for case, _ in CASES:
        for dt, pr in ((np.float64, "textbook"), (np.float32, "stable"),
                       (np.float32, "textbook")):
            _, report = _compare(numpy_port.port(dt, pr), seed, family, case)
            assert _values_pass(report), report.message()


@pytest.mark.parametrize("case", [c for c, _ in CASES])
@pytest.mark.parametrize("seed", SEEDS)
def test_float32_textbook_port_fails_hard_naming_the_projection(seed, case):
    s, report = _compare(numpy_port.port(np.float32, "textbook"), seed, "hard", case)
    msg = report.message()
    print(msg)
    assert not _values_pass(report)
    assert "none of the known mistakes" not in msg
    assert report.cause.startswith(testing.TEXTBOOK_MISTAKE), msg
    # The Gaussians named, with their condition numbers: the needles of scale 1e3 (hard's
    # ill-conditioned case), nothing else.
    named = [int(i) for i in re.findall(r"(\d+) \(condition ", report.cause)]
    assert named
    assert np.all(np.exp(s["scales"][named, 0]) > 999.0)


@pytest.mark.parametrize("seed", range(10))
def test_a_three_sigma_footprint_fails_check_port_on_every_seed(seed):
    """Issue #51: a port that caps the footprint at 3σ (INRIA's) instead of the oracle's
    3.33σ fails check_port on every seed (its radii, and the pixels between 3 and 3.33σ where
    α still reaches 1/255), with no wrong cause named: the oracle cannot render that
    mistake, so it says so."""
    render = numpy_port.port(np.float32, "stable", max_extent_sigma=3.0)
    report = testing.check_port(render, seed=seed, families=ORDINARY, check=False)
    assert report.failing, report.message()
    msg = report.message()
    assert "likely cause: none of the known mistakes" in msg or "not tried" in msg, msg
    for fam in report.failing:
        assert not [c for c in report.families[fam].causes if c], msg


def test_a_mistake_that_moves_the_needles_explains_nothing():
    """On ``hard`` the xyzw hypothesis moves the needles, so the oracle rendered under it
    sets much of the image aside (97 % before the per-pixel conic bound): it must not
    "explain" the textbook port's failures (it was named before the naming rule)."""
    s, report = _compare(numpy_port.port(np.float32, "textbook"), 1, "hard", 0)
    xyzw = dict(report.candidates)["the port reads quaternions as xyzw, not wxyz"]
    assert xyzw >= report.base_failing
    assert report.cause.startswith(testing.TEXTBOOK_MISTAKE)


def test_ill_conditioned_threshold_separates_the_families():
    """TEXTBOOK_ROUNDING·u·condition ≥ 1 holds for no Gaussian of the ordinary families
    and for every needle of ``hard`` the oracle draws."""
    for family in ORDINARY + ("hard",):
        s, cam, _ = _case(0, family, 0)
        d = unseen.render(**s, camera=cam, diagnostics=True)["diagnostics"]
        ill = testing.textbook_ill_conditioned(d)
        if family != "hard":
            assert len(ill) == 0 and d["condition"].max() < 200, family
        else:
            needles = np.flatnonzero((np.exp(s["scales"][:, 0]) > 999.0)
                                     & (d["condition"] > 0))
            assert set(needles) == set(ill)


def test_conics_alone_name_the_projection():
    """A port whose images pass but whose conics of ill-conditioned Gaussians are off (its
    images computed otherwise) is named from the conics."""
    s, cam, bg = _case(1, "hard", 1)
    stable = numpy_port.port(np.float32, "stable")
    textbook = numpy_port.port(np.float32, "textbook")

    def port(scene, camera, *, background):
        out = stable(scene, camera, background=background)
        out["conics"] = textbook(scene, camera, background=background)["conics"]
        return out

    report = testing.compare_render(port, s, cam, background=bg, check=False,
                                     max_excluded_fraction=testing.HARD_MAX_EXCLUDED_FRACTION)
    assert [f.quantity for f in report.failures] == ["conics"]
    assert report.cause.startswith(testing.TEXTBOOK_MISTAKE), report.message()
    # ... and not from conics of other Gaussians: the same port with the ordinary family.
    s, cam, bg = _case(1, "random", 1)
    report = testing.compare_render(port, s, cam, background=bg, check=False)
    assert report.ok


# Before the per-pixel conic bound and the log-form α margin (SPEC.md §8.1) the oracle set
# aside 51–83 % of hard on 19 of 80 cases; with them only seed 35 at 128×96 exceeded the
# bound, by a genuine near tie (two image-wide Gaussians of the large half-transparent group
# 1 ulp apart in z). Since the generator draws depths DEPTH_SEPARATION apart the largest
# share is 29 % (seed 35); near_plane seed 75 (two ~50 px footprints 2 ulps apart, 4.1 %)
# was the one ordinary case of seeds 0–99 above MAX_EXCLUDED_FRACTION, now 1.05 % at most.


def _largest_set_aside(families, seeds):
    """Per (family, case): the seeds whose diagnostics set aside more than the family's
    bound, with unseen as the port (the diagnostics alone)."""
    over = {}
    for fam in families:
        bound = (testing.HARD_MAX_EXCLUDED_FRACTION if fam == "hard"
                 else testing.MAX_EXCLUDED_FRACTION)
        for seed in seeds:
            for case, _ in CASES:
                s, cam, bg = _case(seed, fam, case)
                d = unseen.render(**s, camera=cam, background=list(bg),
                                  diagnostics=True)["diagnostics"]
                aside = ((d["pixel_flags"] & testing.PIXEL_FORWARD_FLAGS) != 0).mean()
                if aside > bound:
                    over.setdefault((fam, case), []).append((seed, round(float(aside), 3)))
    return over


def test_oracle_stays_within_its_bound_on_hard():
    """Issue #51: unseen as the port stays within HARD_MAX_EXCLUDED_FRACTION on ``hard``
    for seeds 0–39 at check_port's sizes (≈ 8 s)."""
    assert _largest_set_aside(["hard"], range(40)) == {}


def test_the_ordinary_bound_never_fails_a_correct_port():
    """Issue #51: on the ordinary families the oracle sets aside at most
    MAX_EXCLUDED_FRACTION for seeds 0–99 at check_port's sizes (≈ 50 s)."""
    assert _largest_set_aside(ORDINARY, range(100)) == {}


def test_drawn_depths_are_separated():
    """The ordinary families' camera depths are DEPTH_SEPARATION apart (relative);
    ``_separated`` keeps the depths it does not move bit for bit."""
    z = np.array([1.0, 3.0, 1.0 + 1e-9, 2.0, 1.0 + 2e-6, 3.0 - 1e-7])
    out = testing._separated(z)
    assert out[0] == 1.0 and out[3] == 2.0 and out[5] == 3.0 - 1e-7  # the lower of a pair stays
    gaps = np.diff(np.sort(out)) / np.sort(out)[:-1]
    assert gaps.min() >= testing.DEPTH_SEPARATION * (1 - 1e-9)
    for fam in ORDINARY:  # (hard draws exact ties and corner Gaussians on purpose)
        s, cam = testing.scene(6000, 3, 75, width=128, height=96, family=fam)
        vm = np.asarray(cam.viewmat, np.float64)
        zc = np.sort((s["means"].astype(np.float64) @ vm[:3, :3].T + vm[:3, 3])[:, 2])
        # (float32 means move z by ulps of its terms: well within half the separation.)
        assert (np.diff(zc) / zc[1:]).min() > 0.5 * testing.DEPTH_SEPARATION, fam


def test_a_float64_port_is_not_told_the_float32_textbook_projection():
    """Issue #70: the textbook cause is float32 arithmetic. The float32 textbook port with its
    outputs widened to float64 (what the harness sees of a float64 port) fails ``hard`` as
    before but is not told the float32 projection; a note says what the footprints hold."""
    inner = numpy_port.port(np.float32, "textbook")

    def widened(scene, camera, *, background):
        return {k: np.asarray(v).astype(np.float64) if np.asarray(v).dtype == np.float32
                else v for k, v in inner(scene, camera, background=background).items()}

    for seed in SEEDS:
        _, report = _compare(widened, seed, "hard", 0)
        msg = report.message()
        assert not _values_pass(report), msg
        assert not report.cause.startswith(testing.TEXTBOOK_MISTAKE), msg
        assert "named only for a float32 port" in msg, msg
