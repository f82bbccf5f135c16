"""Golden renders from an independent Dr.Jit (LLVM, float64) implementation of 3DGS
EWA splatting with gsplat's conventions, and SH basis values from Dr.Jit's sh_eval.

Writes reference_data/drjit/raster/<case>/ {scene.ply, cameras.json, rgb.exr, alpha.exr,
depth.exr, expected_depth.exr, ambiguous.exr, meta.json} and reference_data/drjit/sh/sh.json.

This script does not import or call the unseen crate. It evaluates every Gaussian at every
pixel (no tiles): the tile rule of gsplat only drops pixels where alpha < 1/255 anyway.
Pixels where the float64 reference passes within a relative 2e-5 of a discontinuity
(alpha = 1/255, alpha = 0.99, T = 1e-4) are marked in ambiguous.exr: there an f32
implementation may legitimately take the other branch.

Run:  DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 python make_raster_goldens.py
"""
import json
import os
import sys

import drjit as dr
import numpy as np
from drjit.llvm import Array3f64, Bool, Float64, UInt32

from common import ensure_dir, look_at, write_cameras_json, write_exr, write_inria_ply

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.normpath(os.path.join(HERE, "..", "drjit"))

NEAR, FAR = 0.01, 1e10
EPS2D = 0.3
ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
T_STOP = 1e-4
AMBIGUOUS_REL = 2e-5
C0 = 0.28209479177387814


def quat_to_rot(w, x, y, z):
    n = dr.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def matmul(a, b):
    return [[a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] for j in range(3)]
            for i in range(3)]


def transpose(a):
    return [[a[j][i] for j in range(3)] for i in range(3)]


def leaves(scene, F):
    """The raw parameters as Dr.Jit arrays of type F, one array per component."""
    arr = lambda a: F(np.ascontiguousarray(a, dtype=np.float64))
    k1 = scene["sh_rest"].shape[1]
    return dict(
        means=[arr(scene["means"][:, k]) for k in range(3)],
        log_scales=[arr(scene["log_scales"][:, k]) for k in range(3)],
        quats=[arr(scene["quats"][:, k]) for k in range(4)],
        opacity_logits=[arr(scene["opacity_logits"])],
        sh_dc=[arr(scene["sh_dc"][:, c]) for c in range(3)],
        sh_rest=[[arr(scene["sh_rest"][:, j, c]) for c in range(3)] for j in range(k1)],
    )


def project(scene, cam, P=None, Array3=Array3f64):
    """Vectorized over Gaussians: mean2d, conic, opacity, colour, depth, visible.
    P: the parameters from `leaves` (default: plain float64 arrays of `scene`)."""
    P = P if P is not None else leaves(scene, Float64)
    mx, my, mz = P["means"]
    R = [[float(v) for v in row] for row in cam["R_cw"]]
    t = [float(v) for v in cam["t_cw"]]
    x = R[0][0] * mx + R[0][1] * my + R[0][2] * mz + t[0]
    y = R[1][0] * mx + R[1][1] * my + R[1][2] * mz + t[1]
    z = R[2][0] * mx + R[2][1] * my + R[2][2] * mz + t[2]
    rot = quat_to_rot(*P["quats"])
    s = [dr.exp(v) for v in P["log_scales"]]
    m = [[rot[i][j] * s[j] for j in range(3)] for i in range(3)]
    sigma = matmul(m, transpose(m))
    W = [[R[i][j] for j in range(3)] for i in range(3)]
    sc = matmul(matmul(W, sigma), transpose(W))
    # Python floats: numpy scalars would turn Dr.Jit arrays into numpy object arrays.
    fx, fy, cx, cy = (float(cam[k]) for k in ("fx", "fy", "cx", "cy"))
    w_img, h_img = float(cam["width"]), float(cam["height"])
    tanx, tany = 0.5 * w_img / fx, 0.5 * h_img / fy
    limxp, limxn = (w_img - cx) / fx + 0.3 * tanx, cx / fx + 0.3 * tanx
    limyp, limyn = (h_img - cy) / fy + 0.3 * tany, cy / fy + 0.3 * tany
    zs = dr.select(z > NEAR, z, 1.0)
    tx = zs * dr.clip(x / zs, -limxn, limxp)
    ty = zs * dr.clip(y / zs, -limyn, limyp)
    J = [[fx / zs, 0.0, -fx * tx / (zs * zs)], [0.0, fy / zs, -fy * ty / (zs * zs)]]
    JS = [[J[a][0] * sc[0][b] + J[a][1] * sc[1][b] + J[a][2] * sc[2][b] for b in range(3)] for a in range(2)]
    cov = lambda a, b: JS[a][0] * J[b][0] + JS[a][1] * J[b][1] + JS[a][2] * J[b][2]
    a_, b_, c_ = cov(0, 0) + EPS2D, cov(0, 1), cov(1, 1) + EPS2D
    det = a_ * c_ - b_ * b_
    conic = [c_ / det, -b_ / det, a_ / det]
    mean2d = [fx * x / zs + cx, fy * y / zs + cy]
    opacity = 1.0 / (1.0 + dr.exp(-P["opacity_logits"][0]))
    # colour from Dr.Jit's own SH basis
    c = [float(v) for v in cam["center"]]
    dx, dy, dz = mx - c[0], my - c[1], mz - c[2]
    d = dr.normalize(Array3(dx, dy, dz))
    basis = dr.sh_eval(d, scene["sh_degree"])
    cols = []
    for ch in range(3):
        acc = basis[0] * P["sh_dc"][ch]
        for k in range(1, len(basis)):
            acc += basis[k] * P["sh_rest"][k - 1][ch]
        cols.append(dr.maximum(acc + 0.5, 0.0))
    visible = (z >= NEAR) & (z <= FAR) & (det > 0) & (opacity >= ALPHA_MIN)
    return dict(mean2d=mean2d, conic=conic, opacity=opacity, color=cols, depth=z, visible=visible)


def render(scene, cam, background, P=None, ns=None):
    """ns: a namespace with Float64, UInt32, Bool, Array3f64 (default: drjit.llvm).
    Returns numpy images, or with `P` (AD leaves) the Dr.Jit arrays rgb (3), alpha, D."""
    import drjit.llvm as llvm
    ns = ns or llvm
    Float64, UInt32, Bool = ns.Float64, ns.UInt32, ns.Bool
    p = project(scene, cam, P, ns.Array3f64)
    vis = np.array(dr.detach(p["visible"]))
    depth = np.array(dr.detach(p["depth"]))
    idx = np.nonzero(vis)[0]
    order = idx[np.lexsort((idx, depth[idx]))]  # depth, then index
    w, h = cam["width"], cam["height"]
    pix = dr.arange(UInt32, w * h)
    px = Float64(pix % w) + 0.5
    py = Float64(pix // w) + 0.5
    T = dr.full(Float64, 1.0, w * h)
    C = [dr.zeros(Float64, w * h) for _ in range(3)]
    D = dr.zeros(Float64, w * h)
    done = dr.full(Bool, False, w * h)
    amb = dr.full(Bool, False, w * h)
    G = lambda arr, i: dr.gather(Float64, arr, i)
    for gi in order:
        i = dr.opaque(UInt32, int(gi))
        mxg, myg = G(p["mean2d"][0], i), G(p["mean2d"][1], i)
        A, B, Cc = G(p["conic"][0], i), G(p["conic"][1], i), G(p["conic"][2], i)
        o = G(p["opacity"], i)
        dx, dy = mxg - px, myg - py
        sig = 0.5 * (A * dx * dx + Cc * dy * dy) + B * dx * dy
        raw = o * dr.exp(-sig)
        alpha = dr.minimum(raw, ALPHA_MAX)
        valid = ~done & (sig >= 0) & (alpha >= ALPHA_MIN)
        nT = T * (1 - alpha)
        near = (dr.abs(raw - ALPHA_MIN) <= AMBIGUOUS_REL * ALPHA_MIN) | \
               (dr.abs(raw - ALPHA_MAX) <= AMBIGUOUS_REL * ALPHA_MAX) | \
               (valid & (dr.abs(nT - T_STOP) <= AMBIGUOUS_REL * T_STOP))
        amb |= ~done & near
        stop = valid & (nT <= T_STOP)
        blend = valid & ~stop
        wgt = alpha * T
        for ch in range(3):
            C[ch] = dr.select(blend, C[ch] + G(p["color"][ch], i) * wgt, C[ch])
        D = dr.select(blend, D + G(p["depth"], i) * wgt, D)
        T = dr.select(blend, nT, T)
        done |= stop
        dr.eval(T, C, D, done, amb)
    if P is not None:
        return [C[ch] + T * background[ch] for ch in range(3)], 1 - T, D, np.array(amb), len(order)
    rgb = np.stack([np.array(C[ch]) + np.array(T) * background[ch] for ch in range(3)], -1)
    alpha = 1 - np.array(T)
    Dn = np.array(D)
    ed = Dn / np.maximum(alpha, 1e-10)
    shape = (h, w)
    return (rgb.reshape(h, w, 3), alpha.reshape(shape), Dn.reshape(shape), ed.reshape(shape),
            np.array(amb).astype(np.float64).reshape(shape), len(order))


def random_scene(rng, n, sh_degree, scale_range=(0.02, 0.3), spread=1.0):
    k = (sh_degree + 1) ** 2
    return dict(
        means=np.stack([rng.uniform(-1.2, 1.2, n) * spread, rng.uniform(-0.9, 0.9, n) * spread,
                        rng.uniform(1.5, 6.0, n)], 1),
        log_scales=np.log(rng.uniform(*scale_range, (n, 3))),
        quats=rng.normal(size=(n, 4)),
        opacity_logits=rng.uniform(-2.5, 3.5, n),
        sh_dc=rng.uniform(-1.6, 1.6, (n, 3)),
        sh_rest=rng.uniform(-0.35, 0.35, (n, k - 1, 3)),
        sh_degree=sh_degree,
    )


def camera(name, w, h, fx, fy, eye, target, up=(0, -1, 0), cx=None, cy=None):
    R_wc = look_at(eye, target, up)
    eye = np.asarray(eye, dtype=np.float64)
    R_cw = R_wc.T
    cam = dict(name=name, width=w, height=h, fx=fx, fy=fy, R_wc=R_wc, center=eye,
               cx=cx if cx is not None else 0.5 * w, cy=cy if cy is not None else 0.5 * h)
    cam["R_cw"] = R_cw.tolist()
    cam["t_cw"] = (-(R_cw @ eye)).tolist()
    return cam


def f32_scene(scene):
    """The scene as the PLY stores it (float32), so both sides start from the same values."""
    out = dict(scene)
    for key in ["means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest"]:
        out[key] = scene[key].astype(np.float32).astype(np.float64)
    return out


CASES = [
    # name, n, degree, (w, h), background, camera kwargs, scene kwargs
    ("n10_deg0_64x48", 10, 0, (64, 48), (0.0, 0.0, 0.0), {}, dict(scale_range=(0.1, 0.5))),
    ("n100_deg3_96x72_white", 100, 3, (96, 72), (1.0, 1.0, 1.0), {}, {}),
    ("n500_deg5_160x120_bg", 500, 5, (160, 120), (0.2, 0.4, 0.6), {}, {}),
    ("n300_deg3_160x120_offcentre", 300, 3, (160, 120), (0.0, 0.0, 0.0),
     dict(fy_scale=1.2, cx=70.3, cy=66.8, eye=(0.4, -0.3, -0.5), target=(0.1, 0.2, 3.0)), {}),
    ("n200_deg5_128x96_wide", 200, 5, (128, 96), (0.1, 0.1, 0.1), {},
     dict(spread=2.5, scale_range=(0.01, 0.6))),
    ("n400_deg1_160x120_near", 400, 1, (160, 120), (0.0, 0.0, 0.0),
     dict(eye=(0.0, 0.0, 1.2)), dict(scale_range=(0.005, 0.15))),
]


def main():
    rng = np.random.Generator(np.random.PCG64(20261122))
    root = ensure_dir(os.path.join(OUT, "raster"))
    for name, n, deg, (w, h), bg, ck, sk in CASES:
        scene = f32_scene(random_scene(rng, n, deg, **sk))
        fx = 0.5 * w / np.tan(np.radians(60) / 2)
        cam = camera(name, w, h, fx, fx * ck.get("fy_scale", 1.0), ck.get("eye", (0.0, 0.0, 0.0)),
                     ck.get("target", (0.0, 0.0, 3.0)), cx=ck.get("cx"), cy=ck.get("cy"))
        rgb, alpha, D, ED, amb, nvis = render(scene, cam, bg)
        d = ensure_dir(os.path.join(root, name))
        write_inria_ply(os.path.join(d, "scene.ply"), scene["means"], scene["log_scales"],
                        scene["quats"], scene["opacity_logits"], scene["sh_dc"], scene["sh_rest"])
        write_cameras_json(os.path.join(d, "cameras.json"), [cam])
        write_exr(os.path.join(d, "rgb.exr"), rgb)
        write_exr(os.path.join(d, "alpha.exr"), alpha)
        write_exr(os.path.join(d, "depth.exr"), D)
        write_exr(os.path.join(d, "expected_depth.exr"), ED)
        write_exr(os.path.join(d, "ambiguous.exr"), amb)
        # The raw values of the first Gaussians, to check that the PLY loads right.
        head = {k: scene[k][:4].tolist() for k in
                ["means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest"]}
        with open(os.path.join(d, "params_head.json"), "w") as f:
            json.dump(head, f)
        meta = dict(case=name, gaussians=n, visible=nvis, sh_degree=deg, width=w, height=h,
                    background=list(bg), ambiguous_pixels=int(amb.sum()),
                    tool=f"drjit {dr.__version__} (LLVM backend, float64)",
                    # The convention profile (SPEC.md §5.2): ALPHA_MAX = 0.99 is `inria`'s clamp.
                    conventions="inria",
                    generator="reference_data/generate/make_raster_goldens.py")
        with open(os.path.join(d, "meta.json"), "w") as f:
            json.dump(meta, f, indent=1)
        print(f"{name}: {nvis} visible, {int(amb.sum())} ambiguous pixels")

    # SH basis values, degrees 0..5, from Dr.Jit's sh_eval on random unit directions.
    v = rng.normal(size=(256, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    d = Array3f64(Float64(v[:, 0]), Float64(v[:, 1]), Float64(v[:, 2]))
    # Constant bands come back as size-1 arrays: broadcast them.
    basis = np.stack([np.broadcast_to(np.array(b), (256,)) for b in dr.sh_eval(d, 5)], 1)
    # Sanity: the first bands match the 3DGS constants (same basis, same signs).
    assert np.allclose(basis[:, 1], -0.4886025119029199 * v[:, 1], atol=1e-14)
    assert np.allclose(basis[:, 3], -0.4886025119029199 * v[:, 0], atol=1e-14)
    sh_dir = ensure_dir(os.path.join(OUT, "sh"))
    with open(os.path.join(sh_dir, "sh.json"), "w") as f:
        json.dump(dict(tool=f"drjit {dr.__version__} sh_eval (float64)", degree=5,
                       directions=v.tolist(), values=basis.tolist()), f)
    print("sh: 256 directions")


if __name__ == "__main__":
    sys.exit(main())
