"""Gradient goldens from Dr.Jit's automatic differentiation (LLVM, float64) of an
independent reference renderer: the projection of make_raster_goldens.py, and the blend
vectorized over all (pixel, Gaussian) pairs in depth order, with transmittance as an
exclusive block prefix sum of log(1 - alpha) (one AD graph instead of a Python loop, which
Dr.Jit's reverse mode differentiates slowly). The exclusive 1e-4 stop becomes
`blended = valid & prod(1 - alpha) up to and including this Gaussian > 1e-4`, exact since
the product only decreases.

Loss L = sum(w_rgb * rgb) + sum(w_alpha * alpha) + sum(w_depth * D) with seeded random
weights that are zero on ambiguous pixels (where an f32 renderer may branch differently).
Writes reference_data/drjit/grad/<case>/ {scene.ply, cameras.json, weights_{rgb,alpha,depth}.npy,
grads.json, meta.json}. Does not import the unseen crate.

Run:  DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 python make_grad_goldens.py
"""
import json
import os

import drjit as dr
import drjit.llvm.ad as ad
import numpy as np

from common import ensure_dir, write_cameras_json, write_inria_ply
from make_raster_goldens import (ALPHA_MAX, ALPHA_MIN, AMBIGUOUS_REL, OUT, T_STOP, camera,
                                 f32_scene, leaves, project, random_scene)

CASES = [
    # name, n, degree, (w, h), background, camera kwargs, scene kwargs
    ("n20_deg0_48x36", 20, 0, (48, 36), (0.0, 0.0, 0.0), {}, dict(scale_range=(0.1, 0.5))),
    ("n40_deg3_64x48_bg", 40, 3, (64, 48), (0.3, 0.6, 0.9), {}, dict(scale_range=(0.05, 0.4))),
    ("n50_deg5_64x48", 50, 5, (64, 48), (0.1, 0.1, 0.1), {}, dict(scale_range=(0.05, 0.4))),
    ("n30_deg1_56x40_offcentre", 30, 1, (56, 40), (0.0, 0.0, 0.0),
     dict(fy_scale=1.15, cx=25.3, cy=22.1, eye=(0.3, -0.2, -0.4), target=(0.1, 0.1, 3.0)),
     dict(scale_range=(0.05, 0.4))),
    ("n40_deg3_48x36_wide", 40, 3, (48, 36), (0.0, 0.0, 0.0), {},
     dict(spread=2.5, scale_range=(0.05, 0.8))),
]


def blend_pairs(scene, cam, bg, P):
    """Differentiable render: Dr.Jit arrays rgb (3), alpha, D and the numpy ambiguity mask."""
    F, U = ad.Float64, ad.UInt32
    p = project(scene, cam, P, ad.Array3f64)
    vis = np.array(dr.detach(p["visible"]))
    depth = np.array(dr.detach(p["depth"]))
    idx = np.nonzero(vis)[0]
    order = idx[np.lexsort((idx, depth[idx]))].astype(np.uint32)
    n = len(order)
    w, h = cam["width"], cam["height"]
    k = dr.arange(U, w * h * n)
    pix, slot = k // n, k % n
    gi = dr.gather(U, U(order), slot)
    G = lambda arr: dr.gather(F, arr, gi)
    px, py = F(pix % w) + 0.5, F(pix // w) + 0.5
    dx, dy = G(p["mean2d"][0]) - px, G(p["mean2d"][1]) - py
    A, B, C = (G(v) for v in p["conic"])
    sigma = 0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy
    raw = G(p["opacity"]) * dr.exp(-sigma)
    alpha = dr.minimum(raw, ALPHA_MAX)
    valid = (sigma >= 0) & (alpha >= ALPHA_MIN)
    L = dr.select(valid, dr.log(1 - alpha), 0.0)
    S = dr.block_prefix_sum(L, n, exclusive=True)
    t_before, t_after = dr.exp(S), dr.exp(S + L)
    blended = valid & (dr.detach(t_after) > T_STOP)
    wgt = dr.select(blended, alpha * t_before, 0.0)
    t_final = dr.exp(dr.block_sum(dr.select(blended, L, 0.0), n))
    rgb = [dr.block_sum(wgt * G(p["color"][c]), n) + t_final * bg[c] for c in range(3)]
    D = dr.block_sum(wgt * G(p["depth"]), n)
    # Ambiguous pixels: some pair lies within a relative 2e-5 of a threshold.
    r, ta = np.array(dr.detach(raw)), np.array(dr.detach(t_after))
    vb = np.array(valid)
    near = (np.abs(r - ALPHA_MIN) <= AMBIGUOUS_REL * ALPHA_MIN) | \
           (np.abs(r - ALPHA_MAX) <= AMBIGUOUS_REL * ALPHA_MAX) | \
           (vb & (np.abs(ta - T_STOP) <= AMBIGUOUS_REL * T_STOP))
    amb = near.reshape(w * h, n).any(axis=1) if n else np.zeros(w * h, bool)
    return rgb, 1 - t_final, D, amb, n


def main():
    rng = np.random.Generator(np.random.PCG64(777))
    root = ensure_dir(os.path.join(OUT, "grad"))
    for name, n, deg, (w, h), bg, ck, sk in CASES:
        scene = f32_scene(random_scene(rng, n, deg, **sk))
        fx = 0.5 * w / np.tan(np.radians(60) / 2)
        cam = camera(name, w, h, fx, fx * ck.get("fy_scale", 1.0), ck.get("eye", (0.0, 0.0, 0.0)),
                     ck.get("target", (0.0, 0.0, 3.0)), cx=ck.get("cx"), cy=ck.get("cy"))
        P = leaves(scene, ad.Float64)
        flat = [v for key, group in P.items()
                for v in ([x for row in group for x in row] if key == "sh_rest" else group)]
        for v in flat:
            dr.enable_grad(v)
        rgb, alpha, D, amb, nvis = blend_pairs(scene, cam, bg, P)
        npix = w * h
        keep = (~amb.astype(bool)).astype(np.float64)
        w_rgb = rng.uniform(-1, 1, (npix, 3)) * keep[:, None] / npix
        w_alpha = rng.uniform(-1, 1, npix) * keep / npix
        w_depth = rng.uniform(-0.3, 0.3, npix) * keep / npix
        loss = dr.sum(alpha * ad.Float64(w_alpha)) + dr.sum(D * ad.Float64(w_depth))
        for ch in range(3):
            loss += dr.sum(rgb[ch] * ad.Float64(np.ascontiguousarray(w_rgb[:, ch])))
        dr.backward(loss)
        g = lambda v: np.array(dr.grad(v))
        grads = dict(
            means=np.stack([g(v) for v in P["means"]], 1).tolist(),
            log_scales=np.stack([g(v) for v in P["log_scales"]], 1).tolist(),
            quats=np.stack([g(v) for v in P["quats"]], 1).tolist(),
            opacity_logits=g(P["opacity_logits"][0]).tolist(),
            sh_dc=np.stack([g(v) for v in P["sh_dc"]], 1).tolist(),
            sh_rest=(np.stack([np.stack([g(v) for v in row], 1) for row in P["sh_rest"]], 1).tolist()
                     if P["sh_rest"] else [[] for _ in range(n)]),
        )
        d = ensure_dir(os.path.join(root, name))
        write_inria_ply(os.path.join(d, "scene.ply"), scene["means"], scene["log_scales"],
                        scene["quats"], scene["opacity_logits"], scene["sh_dc"], scene["sh_rest"])
        write_cameras_json(os.path.join(d, "cameras.json"), [cam])
        # The loss weights, float64 as Dr.Jit used them (H, W, 3) and (H, W).
        np.save(os.path.join(d, "weights_rgb.npy"), np.asarray(w_rgb, np.float64).reshape(h, w, 3))
        np.save(os.path.join(d, "weights_alpha.npy"), np.asarray(w_alpha, np.float64).reshape(h, w))
        np.save(os.path.join(d, "weights_depth.npy"), np.asarray(w_depth, np.float64).reshape(h, w))
        with open(os.path.join(d, "grads.json"), "w") as f:
            json.dump(grads, f)
        with open(os.path.join(d, "meta.json"), "w") as f:
            json.dump(dict(case=name, gaussians=n, visible=nvis, sh_degree=deg, width=w, height=h,
                           background=list(bg), loss=float(loss[0]), ambiguous_pixels=int(amb.sum()),
                           tool=f"drjit {dr.__version__} (LLVM AD backend, float64)",
                           # The convention profile (SPEC.md §5.2): ALPHA_MAX = 0.99 is `inria`'s clamp.
                           conventions="inria",
                           generator="reference_data/generate/make_grad_goldens.py"), f, indent=1)
        print(f"{name}: loss {float(loss[0]):.6e}, {int(amb.sum())} ambiguous pixels")


if __name__ == "__main__":
    main()
