"""unseen from Python: the deterministic CPU 3D Gaussian Splatting oracle.

Render, differentiate and compare scenes on NumPy arrays, bit for bit what the `unseen`
command line computes, for any thread count. Parameters follow gsplat's conventions:

=============  ===========  =====================================================
argument       shape        meaning
=============  ===========  =====================================================
``means``      (N, 3)       world positions, float32
``quats``      (N, 4)       rotations, **wxyz**, not necessarily normalised
``scales``     (N, 3)       **log** scales (the activation is ``exp``)
``opacities``  (N,)         **logits** (the activation is the sigmoid)
``sh``         (N, K, 3)    SH coefficients, K = (degree + 1)², DC first
``camera``     `Camera`     from ``K`` (3×3) and the world-to-camera ``viewmat`` (4×4)
=============  ===========  =====================================================

Camera axes are OpenCV's (x right, y down, z forward); pixel centres at (j + 0.5, i + 0.5).
Every scene and gradient array must be float32 and C-contiguous (the camera's ``K`` and
``viewmat`` float64 or float32); ``scales`` and ``opacities`` are the *raw* parameters (log scales,
logits), not the activated ones gsplat's ``rasterization()`` takes. A wrong dtype, order
or shape raises a
``ValueError`` naming the argument and the expected shape. The GIL is released while the
core computes; ``threads`` sets the pool size (the bits do not depend on it).

``conventions`` (``render``, ``backward``) is the convention profile: ``"inria"`` (α clamp
0.99: INRIA, gsplat ≥ 1.5.4; the default) or ``"gsplat"`` (0.999: gsplat 1.0–1.5.3).
``render(..., diagnostics=True)`` also returns, under ``"diagnostics"``, where each pixel's
and Gaussian's discrete decisions came near their thresholds (SPEC.md §8.1);
``unseen.testing`` builds a port's pytest checks on it.
"""

import json as _json

from ._unseen import (
    Camera,
    adam,
    align,
    backward,
    densify,
    extrapolate as _extrapolate,
    frustum,
    gradient_similarity,
    inpaint,
    load_cameras,
    load_ply,
    proximity,
    qa_mask,
    render,
    save_ply,
    ssim,
    versions as _versions,
    view_consistency,
    views,
    warp,
)
from ._unseen import compare_json as _compare_json

__all__ = [
    "Camera",
    "adam",
    "align",
    "backward",
    "compare",
    "densify",
    "extrapolate",
    "frustum",
    "gradient_similarity",
    "inpaint",
    "load_cameras",
    "load_ply",
    "proximity",
    "qa_mask",
    "render",
    "save_ply",
    "ssim",
    "versions",
    "view_consistency",
    "views",
    "warp",
]


def versions():
    """The core's crate version, SPEC.md's conventions version and its numerics revision.

    Record them beside goldens made with this package: a binary of another numerics
    revision may differ in the last bits.
    """
    crate, conventions, numerics = _versions()
    return {"crate": crate, "conventions": conventions, "numerics_revision": numerics}


def compare(run_a, run_b, tolerance=0.0):
    """`unseen compare`: the two run directories step by step, as a dict.

    ``first_divergent`` is the first step (pipeline order) with a file whose largest
    absolute difference exceeds ``tolerance`` (``None`` when the runs agree); ``steps``
    lists every step's files with their largest absolute and ULP differences.
    """
    return _json.loads(_compare_json(str(run_a), str(run_b), float(tolerance)))


def extrapolate(run, candidates, out, *, evaluation=None, dataset=None, preset="quick",
                config=None, resume=False, threads=None):
    """`unseen extrapolate`: the paper's pipeline on a trained run.

    ``config`` is a dict of overrides of the preset (the members of a ``--config`` file).
    Returns ``(scene, steps)``: the final PLY's path (``None`` if the run stopped early)
    and the names of the steps run or reused.
    """
    text = None if config is None else _json.dumps(config)
    return _extrapolate(
        str(run), str(candidates), str(out),
        evaluation=None if evaluation is None else str(evaluation),
        dataset=None if dataset is None else str(dataset),
        preset=preset, config=text, resume=resume, threads=threads,
    )
