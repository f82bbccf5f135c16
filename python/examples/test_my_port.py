"""A test a GPU port copies: let `unseen.testing.check_port` render and differentiate seeded
scenes of every family with unseen (the oracle) and with the port under test, and judge
them (SPEC.md §8.1); and `unseen.testing.compare_adam`, `compare_collide`, `compare_align`,
`compare_loss`, `compare_inpaint`, `compare_frustum`, `compare_views`, `compare_warp` and
`compare_densify` and `compare_qa_mask` judge its optimizer, frustum collision test, depth
alignment, loss, Telea inpainting, region frustums, independent-view selection, DIBR warp,
densification and QA-Mask (replace the `port_*` functions; set ADAM_CONVENTIONS and
LOSS_CONVENTIONS).

To test your port, replace `port_render` / `port_backward` with calls into it (gsplat's
conventions: wxyz quaternions, log scales, logit opacities, (N, K, 3) SH, K and a
world-to-camera viewmat, float32 or float64 camera matrices; the image drawn over
`background`, rgb = C + T·background) and set CONVENTIONS to the profile your port
follows: "inria" (α clamp 0.99: INRIA, gsplat ≥ 1.5.4) or "gsplat" (0.999: gsplat
1.0–1.5.3). As shipped, the "port" is unseen itself, so this file passes.
Run: `python -m pytest examples/test_my_port.py`.

check_port runs every scene family (random, near_plane, rolled, clamp, hard) at two sizes
each, over seeded coloured backgrounds: one family is not a test (a transmittance stop of
1e-3, no stop or the other α clamp pass `random` and `rolled` on most seeds). It sets aside
the few pixels where a correct float32 port may decide a threshold the other way (α near
1/255, T near the 1e-4 stop, depth ties; at most 2 % of the image, 50 % on `hard`),
compares float32 against float32 at twice SPEC.md §8's levels, and on failure names per
family every failing quantity, its worst pixel or Gaussian, the Gaussians only one side
draws and — when one explains it clearly better than every other — the mistake (another
α clamp, pixel centres without the 0.5 offset, an SH band of the wrong sign, xyzw
quaternions, a camera-to-world viewmat, INRIA's near plane 0.2, α·bg or no background,
a transmittance stop of 1e-3, missing cut-offs, and — on `hard`, whose needles of scale 1e3
are the ill-conditioned case — a float32 projection of the textbook form J·Σc·Jᵀ with
det = a·c − b², listing the Gaussians whose thin axis it loses: port the stable form of
SPEC.md §5.1 instead).
"""

import pytest

import unseen
from unseen import testing

CONVENTIONS = "inria"


def port_render(scene, camera, *, background):
    """The port under test: rgb (H, W, 3) and alpha (H, W), float32, drawn over
    `background` (three floats). May also return the per-Gaussian intermediates (means2d,
    conics, colors, depths, opacities, radii): they are compared too, and name the
    failing stage."""
    out = unseen.render(**scene, camera=camera, background=list(background),
                        conventions=CONVENTIONS)
    return {k: out[k] for k in ("rgb", "alpha", "means2d", "conics", "colors", "radii")}


def port_backward(scene, camera, grad_rgb, *, background):
    """The port under test: gradients of sum(grad_rgb * rgb) for every raw parameter."""
    g = unseen.backward(**scene, camera=camera, grad_rgb=grad_rgb,
                        background=list(background), conventions=CONVENTIONS)
    return {k: g[k] for k in ("means", "quats", "scales", "opacities", "sh")}


@pytest.mark.parametrize("seed", [0, 1])
def test_port_matches_the_oracle(seed):
    report = testing.check_port(port_render, port_backward, conventions=CONVENTIONS,
                                seed=seed)
    print(report.message())


# -- Adam (SPEC.md §14.2) ---------------------------------------------------------------
#: The constants your optimizer follows: "pytorch" (torch.optim.Adam's Python-float β, as
#: INRIA's code trains; 1 − β2 = 0.001) or "unseen" (float32 β; 1 − β2 = 0.00099998713).
ADAM_CONVENTIONS = "pytorch"


def port_adam(params, grads, *, lr, betas, eps):
    """The port under test: Adam from zero moments over `grads` (one row per step) on the
    float32 `params`; params, exp_avg and exp_avg_sq after the last step (or every step)."""
    return unseen.adam(params, grads, lr=lr, betas=betas, eps=eps, conventions=ADAM_CONVENTIONS)


@pytest.mark.parametrize("seed", range(4))
def test_adam_matches_the_oracle(seed):
    report = testing.compare_adam(port_adam, seed=seed, conventions=ADAM_CONVENTIONS)
    print(report.message())
    assert report.ok, report.message()


# -- Frustum collisions (SPEC.md §16.1), depth alignment (§17), the loss (§13, §14.1) -----
#: The SSIM border your loss follows: "inria" (zero padding), "valid" (pytorch-msssim) or
#: "reflect" (torchmetrics).
LOSS_CONVENTIONS = "inria"


def port_collide(a, b, faces):
    """The port under test: whether two frustums ((8, 3) vertices, their faces) intersect,
    touching included; or {"intersect": bool, "distance": float}."""
    return unseen.proximity(a, b)["intersect"]


def port_align(estimate, depth, *, space, threshold, method):
    """The port under test: (scale, offset) of scale·estimate + offset ≈ depth (or 1/depth
    for space="disparity"), by RANSAC with a relative threshold or by least squares."""
    fit = unseen.align(estimate, depth, space=space, threshold=threshold, method=method)
    return fit["scale"], fit["offset"]


def port_loss(x, y):
    """The port under test: any of ssim, l1 and INRIA's loss 0.8·L1 + 0.2·(1 − SSIM)."""
    out = unseen.ssim(x, y, conventions=LOSS_CONVENTIONS)
    return {"ssim": out["ssim"], "l1": out["l1"],
            "loss": 0.8 * out["l1"] + 0.2 * (1 - out["ssim"])}


def port_inpaint(image, mask, radius):
    """The port under test: Telea inpainting (OpenCV's INPAINT_TELEA) of a uint8 or float32
    (H, W, C) image where the bool (H, W) mask is True; the image's shape and dtype."""
    return unseen.inpaint(image, mask, radius=radius)["image"]


def port_frustum(mask, depth, k, viewmat, outline):
    """The port under test: the (V, 3) vertices of the region's frustum (any order)."""
    cam = unseen.Camera(k, viewmat, mask.shape[1], mask.shape[0])
    return unseen.frustum(cam, mask, depth=depth, outline=outline)["vertices"]


def port_views(frustums, centers):
    """The port under test: the independent views, greedy in candidate order, and their
    closed nearest-neighbour tour (optionally the colliding pairs and the gaps)."""
    return unseen.views(frustums, centers)


def port_warp(image, depth, source, target, *, footprint, depth_tolerance, close_cracks,
              grow_holes):
    """The port under test: the DIBR forward warp into the target camera (cameras as dicts
    of k, viewmat, width, height): a dict of image, depth (0 in holes) and holes."""
    cams = [unseen.Camera(c["k"], c["viewmat"], c["width"], c["height"])
            for c in (source, target)]
    return unseen.warp(image, depth, *cams, footprint=footprint,
                       depth_tolerance=depth_tolerance, close_cracks=close_cracks,
                       grow_holes=grow_holes)


def port_densify(scene, grad_accum, count, *, extent, world_prune, normals):
    """The port under test: one densify-and-prune step (INRIA's thresholds) of a scene of
    gsplat-convention arrays; split children at mean + R·(s⊙normals[c, i])."""
    keys = ("means", "quats", "scales", "opacities", "sh")
    return unseen.densify(*(scene[k] for k in keys), grad_accum, count, extent=extent,
                          world_prune=world_prune, normals=normals)


def port_mask_scene(trained, *, base, sh_degree):
    """The port under test: the QA-Mask scene built from a trained scene."""
    return unseen.qa_mask(**trained, base=list(base), sh_degree=sh_degree)


def port_mask(tuned, camera, *, base, target):
    """The port under test: the (H, W) QA-Mask of a fine-tuned mask scene."""
    return unseen.qa_mask(**tuned, camera=camera, base=list(base), target=list(target))["mask"]


SEEDS = range(4)


def _judge(report):
    print(report.message())
    assert report.ok, report.message()


# One test per stage: delete the ones your port does not implement.
@pytest.mark.parametrize("seed", SEEDS)
def test_collide_matches_the_oracle(seed):
    _judge(testing.compare_collide(port_collide, seed=seed))


@pytest.mark.parametrize("seed", SEEDS)
def test_align_matches_the_oracle(seed):
    _judge(testing.compare_align(port_align, seed=seed))


@pytest.mark.parametrize("seed", SEEDS)
def test_loss_matches_the_oracle(seed):
    _judge(testing.compare_loss(port_loss, seed=seed, conventions=LOSS_CONVENTIONS))


@pytest.mark.parametrize("seed", SEEDS)
def test_inpaint_matches_the_oracle(seed):
    _judge(testing.compare_inpaint(port_inpaint, seed=seed))


@pytest.mark.parametrize("seed", SEEDS)
def test_frustum_matches_the_oracle(seed):
    _judge(testing.compare_frustum(port_frustum, seed=seed))


@pytest.mark.parametrize("seed", SEEDS)
def test_views_match_the_oracle(seed):
    _judge(testing.compare_views(port_views, seed=seed))


@pytest.mark.parametrize("seed", SEEDS)
def test_warp_matches_the_oracle(seed):
    _judge(testing.compare_warp(port_warp, seed=seed))


@pytest.mark.parametrize("seed", SEEDS)
def test_densify_matches_the_oracle(seed):
    _judge(testing.compare_densify(port_densify, seed=seed))


@pytest.mark.parametrize("seed", SEEDS)
def test_qa_mask_matches_the_oracle(seed):
    _judge(testing.compare_qa_mask({"mask_scene": port_mask_scene, "mask": port_mask},
                                   seed=seed))
