"""unseen.testing's own behaviour, with unseen as the port (no torch needed): a port that
differs by float noise passes, every kind of failure is reported in words, and ports with
the mistakes of issue #51's user study — wrappers of unseen.render that emulate them —
fail check_port with their cause named."""

import re

import numpy as np
import pytest

import unseen
from unseen import testing

#: Seeds the wrong ports are tried on (each check_port call ≈ 2–3 s on 2 cores).
SEEDS = (0, 1, 2)
#: Seeds unseen itself, with and without float noise, must pass every family on.
PASS_SEEDS = (0, 1, 2, 3)


def noisy(scene, seed):
    """The scene's means, scales and rotations moved by ±1.2e-7 relative: what another
    summation order or FMA does to a port's intermediates."""
    rng = np.random.default_rng(seed)
    out = dict(scene)
    for k in ("means", "scales", "quats"):
        v = scene[k]
        out[k] = (v * (1 + 1.2e-7 * rng.uniform(-1, 1, v.shape))).astype(np.float32)
    return out


# -- Ports: unseen itself, and wrappers of it that make one mistake each --------------------


def unseen_port(conventions="inria", noise_seed=None, **cutoffs):
    """(render, backward) for check_port: unseen under `conventions`, optionally with
    float noise on the scene, optionally with other cut-offs (forward only)."""

    def prep(s):
        return s if noise_seed is None else noisy(s, noise_seed)

    def render(s, c, *, background):
        return unseen.render(**prep(s), camera=c, background=list(background),
                             conventions=conventions, **cutoffs)

    def backward(s, c, grad_rgb, *, background):
        return unseen.backward(**prep(s), camera=c, grad_rgb=grad_rgb,
                               background=list(background), conventions=conventions)

    return render, (None if cutoffs else backward)


def alpha_background_port():
    """Adds the background as α·bg: C + α·bg, from unseen's C (black background) and α."""

    def render(s, c, *, background):
        out = unseen.render(**s, camera=c)
        out["rgb"] = (out["rgb"] + out["alpha"][..., None] * np.float32(background))
        return out

    def backward(s, c, grad_rgb, *, background):
        # d/dθ Σ v·(C + α·bg) = backward of C plus α's upstream gradient Σ_c v_c·bg_c.
        grad_alpha = np.ascontiguousarray((grad_rgb * np.float32(background)).sum(-1),
                                          np.float32)
        return unseen.backward(**s, camera=c, grad_rgb=grad_rgb, grad_alpha=grad_alpha)

    return render, backward


def near_plane_port(near=0.2):
    """Culls Gaussians with camera z < `near` (INRIA's 0.2), by an opacity under the cull;
    returns the radii too (0 for what it culls)."""

    def cull(s, c):
        z = s["means"].astype(np.float64) @ c.viewmat[2, :3] + c.viewmat[2, 3]
        culled = z < near
        return dict(s, opacities=np.where(culled, np.float32(-100), s["opacities"])), culled

    def render(s, c, *, background):
        s2, _ = cull(s, c)
        return unseen.render(**s2, camera=c, background=list(background))

    def backward(s, c, grad_rgb, *, background):
        s2, _ = cull(s, c)
        return unseen.backward(**s2, camera=c, grad_rgb=grad_rgb, background=list(background))

    return render, backward


#: Each wrong port, the conventions it is judged under, and the cause that must be named.
MISTAKES = {
    "alpha_background": (alpha_background_port, "inria",
                         r"adds the background as α·bg, not T·bg"),
    "stop_1e-3": (lambda: unseen_port(transmittance_stop=1e-3), "inria",
                  r"stops blending at T ≤ 0\.001"),
    "no_stop": (lambda: unseen_port(transmittance_stop=0.0), "inria",
                r"does not stop blending at T ≤ 1e-4"),
    "near_plane_0.2": (near_plane_port, "inria", r"near plane is 0\.2 \(INRIA's\)"),
    "clamp_0.999_for_0.99": (lambda: unseen_port("gsplat"), "inria",
                             r"clamps α at 0\.999 \(conventions='gsplat'\)"),
    "clamp_0.99_for_0.999": (lambda: unseen_port("inria"), "gsplat",
                             r"clamps α at 0\.99 \(conventions='inria'\)"),
}


# -- A correct port passes -------------------------------------------------------------------


@pytest.mark.parametrize("family", ["random", "near_plane", "rolled", "clamp"])
@pytest.mark.parametrize("seed", [0, 1])
def test_float_noise_passes_with_depth(family, seed):
    scene, cam = testing.scene(3000, 3, seed, width=96, height=80, family=family)

    def port(s, c, *, background):
        return unseen.render(**noisy(s, seed), camera=c, conventions="gsplat",
                             background=list(background))

    testing.compare_render(port, scene, cam, conventions="gsplat",
                           outputs=("rgb", "alpha", "depth"))


#: The families a correct port must pass whatever its float noise: not ``hard``. There the
#: forward passes (seeds 1–5, revision 7) but the backward does not: ±1.2e-7 on a needle's
#: parameters (scale 1e3) turns it by ~1e-7 rad, which moves its own means and scales
#: gradients by up to 40 % (seed 1, Gaussian 1252, condition 4e7, not flagged): the noise
#: changes the scene, not just a port's rounding. (Seed 0's ``hard`` fails without noise
#: too: the oracle sets aside more than HARD_MAX_EXCLUDED_FRACTION, SPEC.md §8.1.)
ORDINARY = ("random", "near_plane", "rolled", "clamp")


@pytest.mark.parametrize("seed", PASS_SEEDS)
@pytest.mark.parametrize("noise", [False, True])
def test_unseen_passes_check_port_on_every_family(seed, noise):
    render, backward = unseen_port(noise_seed=seed if noise else None)
    families = ORDINARY if noise else testing.FAMILIES
    report = testing.check_port(render, backward, seed=seed, families=families)
    assert report.ok and list(report.families) == list(families)
    for fam in report.families.values():
        n_fwd, n_bwd = len(testing.CHECK_FORWARD_CASES), len(testing.CHECK_BACKWARD_CASES)
        assert len(fam.reports) == n_fwd + n_bwd
    # Every comparison drew a coloured background of its own.
    bgs = {r.background for f in report.families.values() for r in f.reports}
    assert len(bgs) == len(families) * (n_fwd + n_bwd)
    assert all(max(bg) - min(bg) >= 0.3 for bg in bgs)
    assert "every family passes" in report.message()


# -- Wrong ports fail with their cause named ---------------------------------------------------


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("mistake", list(MISTAKES))
def test_wrong_ports_fail_check_port_with_their_cause_named(mistake, seed):
    make, conventions, cause = MISTAKES[mistake]
    render, backward = make()
    report = testing.check_port(render, backward, conventions=conventions, seed=seed,
                                check=False)
    assert report.failing, mistake
    for name in report.failing:
        causes = report.families[name].causes
        assert len(causes) == 1 and re.search(cause, causes[0]), (name, report.message())
        assert f"{name}: FAILS" in report.message()
    assert "camera-to-world" not in report.message().split("\n-- ")[0]


def test_one_family_is_not_a_test():
    """The user study's finding: the cut-off mistakes and the clamp swap pass `random` and
    `rolled` on some seeds; check_port fails them anyway, on another family."""
    passing_somewhere = set()
    for mistake in ("stop_1e-3", "no_stop", "clamp_0.999_for_0.99"):
        make, conventions, _ = MISTAKES[mistake]
        render, backward = make()
        report = testing.check_port(render, backward, conventions=conventions, seed=0,
                                    check=False)
        assert not report.ok
        if mistake == "no_stop":  # check=True raises with the same per-family message
            with pytest.raises(AssertionError, match=re.escape(report.message().split("[")[0])):
                testing.check_port(render, backward, conventions=conventions, seed=0)
        passing_somewhere |= {f for f, r in report.families.items() if r.ok}
    assert {"random", "rolled"} & passing_somewhere


def test_near_plane_is_never_named_a_viewmat_mistake(monkeypatch):
    """Without the near-plane hypothesis the camera-to-world viewmat explains part of a
    0.2 near plane's failing values (10–64 %; "explains half" named it): the naming rule
    must not name it."""
    render, backward = near_plane_port()
    scene, cam = testing.scene(6000, 3, 0, width=128, height=96, family="near_plane")
    r = testing.compare_render(render, scene, cam, check=False)
    assert r.cause.startswith("the port's near plane is 0.2")
    b = testing.compare_backward(backward, scene, cam, check=False)
    assert b.cause.startswith("the port's near plane is 0.2")
    real = testing.mistakes
    monkeypatch.setattr(testing, "mistakes", lambda *a, **k: [
        m for m in real(*a, **k) if "near plane" not in m.text])
    for rep in (testing.compare_render(render, scene, cam, check=False),
                testing.compare_backward(backward, scene, cam, check=False)):
        viewmat = dict(rep.candidates)["the port takes the viewmat as camera-to-world, not "
                                       "world-to-camera"]
        assert viewmat < rep.base_failing  # it does explain a part ...
        assert rep.cause == ""  # ... but is not named
        assert "none of the known mistakes explains the failing values clearly" in rep.message()
        assert "closest: the port takes the viewmat as camera-to-world" in rep.message()


def test_naming_rule():
    base = 1000
    named = testing._named
    assert named([(0, "a"), (400, "b")], base) == "a"
    assert named([(90, "a"), (400, "b")], base) == "a"
    assert named([(110, "a"), (900, "b")], base) == ""  # leaves more than 10 %
    assert named([(0, "a"), (50, "b")], base) == ""  # b leaves ≤ 10 % as well
    assert named([(60, "a"), (150, "b")], base) == ""  # b leaves < 3× as many
    assert named([(50, "a"), (150, "b")], base) == "a"
    assert named([(0, "a")], base) == "a"
    assert named([], base) == "" and named([(0, "a")], 0) == ""


# -- The background --------------------------------------------------------------------------


def test_the_port_gets_the_background():
    scene, cam = testing.scene(800, 1, 0, width=48, height=32)
    seen = []

    def port(s, c, *, background):
        seen.append(background)
        return unseen.render(**s, camera=c, background=list(background))

    testing.compare_render(port, scene, cam)
    assert seen == [testing.DEFAULT_BACKGROUND]
    testing.compare_render(port, scene, cam, background=(0.1, 0.2, 0.3))
    assert seen[-1] == (0.1, 0.2, 0.3)

    def black(s, c, *, background):
        return unseen.render(**s, camera=c)

    with pytest.raises(AssertionError, match=r"ignores the background \(draws C, not C \+ T·bg\)"):
        testing.compare_render(black, scene, cam)
    # On black the same port passes: why black is not the default.
    testing.compare_render(black, scene, cam, background=(0.0, 0.0, 0.0))


def test_a_port_without_the_background_keyword_is_told_so():
    scene, cam = testing.scene(300, 1, 0, width=32, height=24)

    def old(s, c):
        return unseen.render(**s, camera=c)

    def old_backward(s, c, g):
        return unseen.backward(**s, camera=c, grad_rgb=g)

    with pytest.raises(TypeError, match=r"must accept the keyword argument background: "
                                        r"port\(scene, camera, \*, background\)"):
        testing.compare_render(old, scene, cam)
    with pytest.raises(TypeError, match=r"port_backward\(scene, camera, grad_rgb, \*, "
                                        r"background\)"):
        testing.compare_backward(old_backward, scene, cam)
    with pytest.raises(TypeError, match="keyword argument background"):
        testing.check_port(old)
    # **kwargs is enough.
    testing.compare_render(lambda s, c, **kw: unseen.render(
        **s, camera=c, background=list(kw["background"])), scene, cam)


# -- Culls -----------------------------------------------------------------------------------


def test_gaussians_one_side_culls_are_listed_with_the_oracle_s_reason():
    scene, cam = testing.scene(3000, 1, 0, width=96, height=80, family="near_plane")
    render, _ = near_plane_port()

    def with_radii(s, c, *, background):
        out = render(s, c, background=background)
        z = s["means"].astype(np.float64) @ c.viewmat[2, :3] + c.viewmat[2, 3]
        out["radii"] = np.where((z < 0.2)[:, None], 0, out["radii"])
        return out

    r = testing.compare_render(with_radii, scene, cam, check=False)
    culls = [f for f in r.failures if f.quantity == "culls"]
    assert culls and "the port culls" in culls[0].note
    assert "a near plane of 0.2 instead of 0.01?" in culls[0].note

    # A port that draws Gaussians the oracle culls for their opacity.
    # A port that draws Gaussians the oracle culls: behind the near plane (a failure: it
    # would blend them), for their opacity or off the image (notes: it cannot blend them).
    scene, cam = testing.scene(500, 1, 0, width=48, height=32)
    scene["opacities"][:5] = -10.0  # sigmoid 4.5e-5 < 1/255
    z = scene["means"].astype(np.float64) @ cam.viewmat[2, :3] + cam.viewmat[2, 3]
    scene["means"][5] -= np.float32(z[5] + 1.0) * cam.viewmat[2, :3].astype(np.float32)

    def draws_all(s, c, *, background):
        out = unseen.render(**s, camera=c, background=list(background))
        out["radii"] = np.where(out["radii"] > 0, out["radii"], 3)
        return out

    r = testing.compare_render(draws_all, scene, cam, check=False)
    note = next(f.note for f in r.failures if f.quantity == "culls")
    assert "the port draws 1 Gaussians the oracle culls: 5 (oracle: behind the near plane" in note
    notes = " ".join(r.notes)
    assert "the port draws 5 Gaussians the oracle culls for their opacity" in notes
    assert "whose footprint the oracle finds off the image" in notes
    assert [f.quantity for f in r.failures] == ["culls"]


# -- Failures in words -------------------------------------------------------------------------


def test_failures_are_reported_in_words():
    scene, cam = testing.scene(500, 1, 0, width=48, height=32)
    good = unseen.render(**scene, camera=cam)
    black = (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="background: give the background"):
        testing.compare_render(good, scene, cam)
    with pytest.raises(AssertionError, match=r"alpha: the port returned no such output"):
        testing.compare_render({"rgb": good["rgb"]}, scene, cam, background=black)
    with pytest.raises(AssertionError, match=r"rgb: the port returned shape \(32, 48\), the oracle \(32, 48, 3\)"):
        testing.compare_render({"rgb": good["alpha"], "alpha": good["alpha"]}, scene, cam,
                               background=black)
    with pytest.raises(ValueError, match="outputs: expected names among"):
        testing.compare_render(good, scene, cam, outputs=("expected_depth",), background=black)
    r = testing.compare_render({"rgb": good["rgb"], "alpha": good["alpha"] + 0.01}, scene, cam,
                               check=False, background=black)
    assert not r.ok and r.failures[0].quantity == "alpha" and r.diagnosed
    assert "likely cause: none of the known mistakes" in r.message()
    assert "not tried: a footprint radius of 3σ" in r.message()
    hard, hcam = testing.scene(2000, 1, 0, width=48, height=32, family="hard")
    r = testing.compare_render(unseen.render(**hard, camera=hcam), hard, hcam, check=False,
                               max_excluded_fraction=0.001, background=black)
    assert r.excluded_fraction > 0.001
    assert [f.quantity for f in r.failures] == ["excluded pixels"]
    assert not r.diagnosed and "likely cause" not in r.message()


def test_backward_says_what_it_cannot_try():
    scene, cam = testing.scene(800, 1, 0, width=48, height=32, family="clamp")

    def off(s, c, g, *, background):
        out = unseen.backward(**s, camera=c, grad_rgb=g, background=list(background))
        out["opacities"] = out["opacities"] * 1.1
        return out

    r = testing.compare_backward(off, scene, cam, check=False)
    assert not r.ok and r.cause == ""
    assert "not tried: cut-off mistakes" in r.message()

