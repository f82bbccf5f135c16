"""The QA-Mask for ports: ``compare_qa_mask``'s cases and known mistakes (SPEC.md §15.1).

Two parts of the procedure are the QA-Mask's own (its fine-tune is training, judged stage by
stage: the rasterizer, the loss and Adam): building the mask scene from a trained one, and
the mask of a fine-tuned mask scene — its render over the base colour, projected on the
base–target colour axis and clamped to [0, 1]. The scene is judged bit for bit but for the
DC term (``(base − 0.5)/C0`` in float32 by any order: ``DC_ULPS``); the mask per pixel by
the render's own tolerance (§8.1) carried through the projection, with the pixels the
render's diagnostics flag set aside.
"""

import numpy as np

from ._stage import StageMistake

#: The DC term may lie this many float32 ulps from the oracle's.
DC_ULPS = 2
#: SH's zeroth-band constant.
C0 = 0.28209479177387814


def qa_mask_case(seed, testing):
    """A seeded case: a ``trained`` scene (``testing.scene``'s ``random`` family, 1 500
    Gaussians, SH degree 3) and its ``camera`` (96×72); ``base`` and ``target`` colours
    (red on black, the paper's, on even seeds; a random pair with ``|b − t|² ≥ 0.25`` on odd
    ones); ``sh_degree`` 5 (3 or 4 on every third seed); and ``tuned``, a mask scene as a
    fine-tune leaves it (SH rest of magnitude 0.1–0.3)."""
    rng = np.random.default_rng(np.random.PCG64(80_000 + seed))
    trained, camera = testing.scene(1500, 3, seed, width=96, height=72, family="random")
    if seed % 2:
        while True:
            base, target = rng.uniform(0, 1, 3), rng.uniform(0, 1, 3)
            if np.sum((base - target) ** 2) >= 0.25:
                break
    else:
        base, target = np.array([1.0, 0, 0]), np.zeros(3)
    degree = (3, 4)[seed // 3 % 2] if seed % 3 == 2 else 5
    n = len(trained["means"])
    k = (degree + 1) ** 2
    tuned = dict(trained)
    dc = ((base.astype(np.float32) - np.float32(0.5)) / np.float32(C0)).astype(np.float32)
    sh = np.zeros((n, k, 3), np.float32)
    sh[:, 0] = dc
    sh[:, 1:] = rng.normal(0, rng.uniform(0.1, 0.3), (n, k - 1, 3))
    tuned["sh"] = sh
    return {"trained": trained, "camera": camera, "base": tuple(map(float, base)),
            "target": tuple(map(float, target)), "sh_degree": degree, "tuned": tuned}


QA_MASK_MISTAKES = (
    StageMistake("dc_unshifted", "the base colour's DC without the −0.5 (DC = base / C0)"),
    StageMistake("rest_kept", "the trained scene's higher SH kept (not zeroed)"),
    StageMistake("target_background", "the mask rendered over the target colour, not the base"),
    StageMistake("no_clamp", "the projection not clamped to [0, 1]"),
    StageMistake("mean_channel", "the mask from the mean of the channels, not the projection "
                 "on the base–target axis"),
    StageMistake("opacity", "1 − α (the opacity baseline), not the QA-Mask"),
)


def project(rgb, base, target, clamp=True):
    """The mask value of rendered colours ``rgb`` (…, 3): their projection on the
    base–target axis, ``((c − t)·(b − t)) / |b − t|²``, clamped to [0, 1]."""
    d = np.asarray(base, np.float64) - target
    v = ((np.asarray(rgb, np.float64) - target) @ d) / (d @ d)
    return np.clip(v, 0, 1) if clamp else v
