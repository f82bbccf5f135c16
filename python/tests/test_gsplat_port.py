"""A real third-party port through unseen.testing: gsplat 1.5.3's pure-PyTorch reference
functions (`gsplat.cuda._torch_impl`: quaternion/scale covariance, projection, SH, tile
intersection) with a PyTorch compositor for the step gsplat implements only in CUDA,
run on the CPU in float32. Under conventions='gsplat' (its α clamp, 0.999) it must pass on
every generated scene family; under 'inria' it must fail on the clamp family with the
clamp named; four deliberately wrong ports must fail with their cause named (one through
check_port: α·bg instead of T·bg, invisible on black).

Skipped, with the reason printed, where torch or gsplat is missing (installing them takes
about 2 minutes and 5.5 GB here: `pip install torch gsplat==1.5.3`). UNSEEN_PORT_SEEDS
sets how many seeds per family run (default 2; the issue's acceptance run used 20).
"""

import os

import numpy as np
import pytest

from unseen import testing as ut

try:
    import torch
    from gsplat.cuda import _torch_impl as gs
except Exception as e:  # pragma: no cover - missing, or a broken install (OSError on load)
    pytest.skip(f"gsplat's torch reference is not installed ({e}); "
                "pip install torch gsplat==1.5.3 to run the port tests",
                allow_module_level=True)

SEEDS = range(int(os.environ.get("UNSEEN_PORT_SEEDS", "2")))
FAMILIES = ("random", "near_plane", "rolled", "clamp")  # `hard`: see its own test
ALPHA_THRESHOLD = 1.0 / 255.0
TRANSMITTANCE_STOP = 1e-4
TILE = 16


def _composite(means2d, conics, opac, colors, depths, flat_ids, offsets, width, height,
               background, max_alpha, pixel_offset, transmittance_stop=TRANSMITTANCE_STOP,
               dtype=torch.float32):
    """Front-to-back blending of each 16×16 tile's depth-sorted list (gsplat's rules:
    skip σ < 0 and α < 1/255, α clamped at `max_alpha`, stop before T·(1 − α) ≤ 1e-4),
    vectorised per tile with a cumulative product, differentiable by autograd."""
    tw, th = (width + TILE - 1) // TILE, (height + TILE - 1) // TILE
    rgb = torch.zeros((height, width, 3), dtype=dtype)
    rgb = rgb + torch.tensor(background, dtype=dtype)
    alpha = torch.zeros((height, width), dtype=dtype)
    ends = torch.cat([offsets.flatten()[1:], torch.tensor([flat_ids.numel()])])
    out_rgb, out_a, idx = [], [], []
    for t in range(tw * th):
        ty, tx = divmod(t, tw)
        y0, x0 = ty * TILE, tx * TILE
        ys = torch.arange(y0, min(y0 + TILE, height))
        xs = torch.arange(x0, min(x0 + TILE, width))
        yy, xx = (g.reshape(-1) for g in torch.meshgrid(ys, xs, indexing="ij"))
        py, px = yy.to(dtype) + pixel_offset, xx.to(dtype) + pixel_offset
        ids = flat_ids[int(offsets.flatten()[t]):int(ends[t])].long()
        if ids.numel() == 0:
            continue
        dx = means2d[ids, 0][None, :] - px[:, None]
        dy = means2d[ids, 1][None, :] - py[:, None]
        a, b, c = conics[ids, 0], conics[ids, 1], conics[ids, 2]
        sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
        al = torch.clamp(opac[ids][None, :] * torch.exp(-sigma), max=max_alpha)
        valid = (sigma >= 0) & (al >= ALPHA_THRESHOLD)
        al = torch.where(valid, al, torch.zeros_like(al))
        t_incl = torch.cumprod(1.0 - al, dim=1)
        t_before = torch.cat([torch.ones_like(t_incl[:, :1]), t_incl[:, :-1]], dim=1)
        blended = valid & (t_incl > transmittance_stop)
        w = torch.where(blended, al * t_before, torch.zeros_like(al))
        pix = w @ colors[ids]
        t_final = torch.where(blended, 1.0 - al, torch.ones_like(al)).prod(dim=1)
        out_rgb.append(pix + t_final[:, None] * torch.tensor(background, dtype=dtype))
        out_a.append(1.0 - t_final)
        idx.append((yy, xx))
    for (yy, xx), p, a in zip(idx, out_rgb, out_a):
        rgb = rgb.index_put((yy, xx), p)
        alpha = alpha.index_put((yy, xx), a)
    return rgb, alpha


def gsplat_port(max_alpha, *, sh_sign_band1=1.0, pixel_offset=0.5, alpha_background=False,
                transmittance_stop=TRANSMITTANCE_STOP, dtype=torch.float32,
                exact_normalize=False, index_ties=False):
    """The port: gsplat's torch functions, our torch compositor. Returns (render, backward)
    callables for unseen.testing. The keyword arguments make the deliberately wrong ports;
    ``dtype=torch.float64`` runs gsplat's formulas in float64 end to end (the float32
    scene and camera values widened), gradients by autograd. ``exact_normalize`` divides each
    quaternion by its norm before gsplat sees it (``F.normalize``'s 1e-12 floor leaves a
    quaternion of norm 1e-20, one of ``hard``'s cases, unnormalised: a rotation ≈ I).
    ``index_ties`` orders each tile's Gaussians of bit-equal depth by index, the harness's
    convention (SPEC.md §5.3; ``torch.sort`` of gsplat's tile-and-depth keys leaves their
    order open, and ``hard`` draws exact ties on purpose)."""

    def forward(scene, camera, background, grad=False):
        p = {k: torch.tensor(np.asarray(v), dtype=dtype, requires_grad=grad)
             for k, v in scene.items()}
        k = torch.tensor(camera.k, dtype=dtype)[None]
        vm = torch.tensor(camera.viewmat, dtype=dtype)[None]
        w, h = camera.width, camera.height
        quats = p["quats"]
        if exact_normalize:
            quats = quats / torch.linalg.vector_norm(quats, dim=-1, keepdim=True)
        covars, _ = gs._quat_scale_to_covar_preci(
            quats, torch.exp(p["scales"]), compute_preci=False)
        radii, means2d, depths, conics, _ = gs._fully_fused_projection(
            p["means"], covars, vm, k, w, h)
        radii, means2d, depths, conics = radii[0], means2d[0], depths[0], conics[0]
        campos = torch.linalg.inv(vm[0].double())[:3, 3].to(dtype)
        degree = int(round(p["sh"].shape[1] ** 0.5)) - 1
        sh = p["sh"]
        if sh_sign_band1 != 1.0 and degree >= 1:
            sign = torch.ones(sh.shape[1], 1)
            sign[1:4] = sh_sign_band1
            sh = sh * sign
        colors = torch.clamp_min(
            gs._spherical_harmonics(degree, p["means"] - campos, sh) + 0.5, 0.0)
        opac = torch.sigmoid(p["opacities"])
        tw, th = (w + TILE - 1) // TILE, (h + TILE - 1) // TILE
        _, isect_ids, flat_ids = gs._isect_tiles(
            means2d[None].detach(), radii[None], depths[None].detach(), TILE, tw, th)
        offsets = gs._isect_offset_encode(isect_ids, 1, tw, th)
        if index_ties:
            # Stable in (tile, depth), then by index: the same key order, ties by index.
            ids = flat_ids.long()
            order = np.lexsort((ids.numpy(), isect_ids.numpy()))
            flat_ids = flat_ids[torch.from_numpy(order)]
        rgb, alpha = _composite(means2d, conics, opac, colors, depths, flat_ids, offsets,
                                w, h, [0.0] * 3 if alpha_background else list(background),
                                max_alpha, pixel_offset, transmittance_stop, dtype)
        if alpha_background:  # the mistake: C + α·bg
            rgb = rgb + alpha[..., None] * torch.tensor(background, dtype=dtype)
        return p, rgb, alpha, dict(means2d=means2d, conics=conics, colors=colors,
                                   depths=depths, opacities=opac, radii=radii)

    def render(scene, camera, *, background):
        with torch.no_grad():
            _, rgb, alpha, inter = forward(scene, camera, background)
        out = {k: v.detach().numpy() for k, v in inter.items()}
        out.update(rgb=rgb.numpy(), alpha=alpha.numpy())
        return out

    def backward(scene, camera, grad_rgb, *, background):
        p, rgb, _, _ = forward(scene, camera, background, grad=True)
        (rgb * torch.tensor(grad_rgb, dtype=dtype)).sum().backward()
        return {k: v.grad.numpy() for k, v in p.items()}

    return render, backward


GSPLAT_MAX_ALPHA = 0.999  # gsplat 1.5.3 RasterizeToPixels3DGSFwd.cu: min(0.999f, ...)


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("seed", SEEDS)
def test_gsplat_port_passes_under_its_profile(family, seed):
    scene, cam = ut.scene(10_000, 3, seed, width=256, height=256, family=family,
                          dtype=np.float32)
    render, backward = gsplat_port(GSPLAT_MAX_ALPHA)
    r = ut.compare_render(render, scene, cam, conventions="gsplat")
    print(f"{family} seed {seed}: forward set aside {r.excluded_fraction:.4%} {r.excluded}")
    small, small_cam = ut.scene(2_000, 3, seed, width=96, height=80, family=family,
                                dtype=np.float32)
    b = ut.compare_backward(backward, small, small_cam, conventions="gsplat", seed=seed)
    print(f"{family} seed {seed}: backward set aside {b.excluded_fraction:.4%} pixels, "
          f"{b.excluded_gaussians} Gaussians")


def test_gsplat_port_passes_check_port_under_its_profile():
    """check_port: every ordinary family, two forward sizes and one backward, coloured
    backgrounds (≈ 20 s). `hard` has its own test below: gsplat's textbook projection in
    float32 loses the needles' thin axis there."""
    render, backward = gsplat_port(GSPLAT_MAX_ALPHA)
    report = ut.check_port(render, backward, conventions="gsplat", seed=0, families=FAMILIES)
    print(report.message())


def test_gsplat_port_fails_under_inria_on_the_clamp_scene():
    scene, cam = ut.scene(10_000, 3, 0, width=256, height=256, family="clamp",
                          dtype=np.float32)
    render, _ = gsplat_port(GSPLAT_MAX_ALPHA)
    with pytest.raises(AssertionError, match=r"clamps α at 0\.999 \(conventions='gsplat'\)"):
        ut.compare_render(render, scene, cam, conventions="inria")


@pytest.mark.parametrize("mistake, cause", [
    (dict(max_alpha=0.99), r"clamps α at 0\.99 \(conventions='inria'\)"),
    (dict(sh_sign_band1=-1.0), r"SH band 1 has the opposite sign"),
    (dict(pixel_offset=0.0), r"pixel centres at \(j, i\)"),
])
def test_wrong_ports_fail_with_their_cause_named(mistake, cause):
    scene, cam = ut.scene(10_000, 3, 1, width=256, height=256, family="clamp",
                          dtype=np.float32)
    kw = dict(mistake)
    render, backward = gsplat_port(kw.pop("max_alpha", GSPLAT_MAX_ALPHA), **kw)
    with pytest.raises(AssertionError, match=cause) as err:
        ut.compare_render(render, scene, cam, conventions="gsplat")
    print(err.value)


def test_alpha_background_port_fails_check_port_with_its_cause_named():
    render, backward = gsplat_port(GSPLAT_MAX_ALPHA, alpha_background=True)
    report = ut.check_port(render, backward, conventions="gsplat", seed=0,
                           families=("random",), check=False)
    print(report.message())
    assert report.failing == ["random"]
    assert [c[:60] for c in report.families["random"].causes] == [
        "the port adds the background as α·bg, not T·bg (T = 1 − α)"]


def test_a_stop_of_1e3_is_named_forward_and_consistent_backward():
    """The oracle's backward cannot run another stop: check_port names it from the forward,
    and the backward says the gradients are consistent with it."""
    render, backward = gsplat_port(GSPLAT_MAX_ALPHA, transmittance_stop=1e-3)
    report = ut.check_port(render, backward, conventions="gsplat", seed=0,
                           families=("clamp",), check=False)
    print(report.message())
    assert report.families["clamp"].causes == [
        "the port stops blending at T ≤ 0.001, not at T ≤ 1e-4"]
    bwd = report.families["clamp"].reports[-1]
    assert not bwd.ok and bwd.cause == ""
    assert [c.split(" (")[0] for c in bwd.consistent] == [
        "the port stops blending at T ≤ 0.001, not at T ≤ 1e-4"]


def test_gsplat_port_fails_hard_naming_the_ill_conditioned_projection():
    """gsplat's own formulas (Σ2d = J·Σc·Jᵀ, det = a·c − b², in float32) on check_port's
    `hard` family: both forward sizes fail, and the cause named is the textbook projection
    with the Gaussians it concerns (the needles of scale 1e3), never "none of the known
    mistakes" (seeds 0–19 measured: 40 of 40 named; docs/notes/rationale.md §8.1). Forward
    only (≈ 10 s)."""
    render, _ = gsplat_port(GSPLAT_MAX_ALPHA)
    report = ut.check_port(render, conventions="gsplat", seed=1, families=("hard",),
                           check=False)
    print(report.message())
    assert report.failing == ["hard"]
    assert "none of the known mistakes" not in report.message()
    for r in report.families["hard"].reports:
        assert not r.ok and r.cause.startswith(ut.TEXTBOOK_MISTAKE), r.message()


def test_float64_gsplat_port_passes_hard_forward_and_backward():
    """Issue #70: gsplat's formulas in float64 end to end (quaternions normalised exactly,
    ties in index order: the harness's conventions where gsplat's torch functions leave them
    open) pass check_port's ``hard`` family at both forward sizes and the backward size. The
    oracle's backward used to contradict its own forward on the needles (a float64 port
    failed 20 of 20 seeds); the needles' gradients are now set aside as beyond float32 in
    the comparison (a float32 port cannot resolve them) and checked against the f64 twin's
    finite differences in the crate's own tests. Seeds 0–19 measured: 20 of 20 pass
    (UNSEEN_PORT_SEEDS=20; ≈ 0.6 s a seed)."""
    render, backward = gsplat_port(GSPLAT_MAX_ALPHA, dtype=torch.float64, exact_normalize=True,
                                   index_ties=True)
    for seed in SEEDS:
        report = ut.check_port(render, backward, conventions="gsplat", seed=seed,
                               families=("hard",), check=False)
        assert report.ok, report.message()
        bwd = report.families["hard"].reports[-1]
        assert any("beyond float32" in n for n in bwd.notes), bwd.message()


def test_gsplat_port_backward_on_hard_is_named_from_its_forward():
    """Issue #70: given the port's forward (``port_render``, as check_port passes it), a
    failing backward on ``hard`` is named the textbook projection when the port's forward on
    the same scene is: seeds 0–19 measured, 20 of 20 named (≈ 0.4 s a seed)."""
    render, backward = gsplat_port(GSPLAT_MAX_ALPHA)
    for seed in SEEDS:
        s, cam = ut.scene(1500, 3, seed, width=80, height=64, family="hard",
                          dtype=np.float32)
        r = ut.compare_backward(backward, s, cam, conventions="gsplat", check=False,
                                seed=seed, max_excluded_fraction=ut.HARD_MAX_EXCLUDED_FRACTION,
                                port_render=render)
        assert not r.ok and r.cause.startswith(ut.TEXTBOOK_MISTAKE), r.message()


def test_gsplat_port_backward_on_hard_notes_the_projection():
    """Without the port's forward the backward cannot localise the textbook projection (a
    needle's footprint box is the whole image): its failing comparison names no mistake but
    says the scene holds Gaussians that projection cannot resolve (≈ 5 s)."""
    _, backward = gsplat_port(GSPLAT_MAX_ALPHA)
    s, cam = ut.scene(1500, 3, 1, width=80, height=64, family="hard", dtype=np.float32)
    r = ut.compare_backward(backward, s, cam, conventions="gsplat", check=False,
                            max_excluded_fraction=ut.HARD_MAX_EXCLUDED_FRACTION)
    print(r.message())
    assert not r.ok and r.cause == ""
    assert any(n.startswith("the scene holds Gaussians a float32 textbook projection")
               for n in r.notes)
