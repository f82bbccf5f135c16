"""Ground-truth co-visibility for the DIBR test (issue #6, SPEC.md §18), by Mitsuba 3.

For a few pairs of nearby cameras (A -> B) of the bundled scenes, decide for every pixel
of B whether the surface point seen through its centre is also visible from A: Mitsuba
traces B's pixel-centre ray to the surface point p (normal n), and p is visible from A
when n faces A, p projects inside A's image in front of A, and Mitsuba's `ray_test` finds
nothing between p (offset by 1e-4 along n) and A's centre. Pixels of B not visible from
A are the true disocclusions a forward warp A -> B must leave as holes.

The scene geometry is rebuilt from make_scenes.py with the same seed; the script checks
it against the stored depth of B (camera z agrees to 1e-4 relative).

Written: reference_data/mitsuba/dibr/<scene>/<A>__<B>/visible.png (8-bit, 255 = visible)
and reference_data/mitsuba/dibr/meta.json (pairs, tool versions, rules).

Run: DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 python make_dibr_goldens.py
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
import make_scenes as ms  # noqa: E402
from common import ensure_dir  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

HERE = os.path.dirname(__file__)
SCENES = os.path.join(HERE, "..", "scenes")
OUT = os.path.join(HERE, "..", "mitsuba", "dibr")
PAIRS_PER_SCENE = 2
OFFSET = 1e-4


def cameras(name):
    with open(os.path.join(SCENES, name, "cameras.json")) as f:
        cams = json.load(f)
    for c in cams:
        c["R"] = np.array(c["rotation"])
        c["C"] = np.array(c["position"])
    return cams


def pick_pairs(cams, n):
    """Nearby pairs: centres 0.25-0.8 m apart, optical axes within 25 degrees; the n with the
    smallest angle, disjoint."""
    cand = []
    for i, a in enumerate(cams):
        for j, b in enumerate(cams):
            if i == j:
                continue
            d = np.linalg.norm(a["C"] - b["C"])
            cosang = float(a["R"][:, 2] @ b["R"][:, 2])
            ang = np.degrees(np.arccos(min(1.0, cosang)))
            if 0.25 <= d <= 0.8 and ang <= 25.0:
                cand.append((ang + 10.0 * d, i, j))
    cand.sort()
    used, out = set(), []
    for _, i, j in cand:
        if i in used or j in used:
            continue
        used |= {i, j}
        out.append((cams[i], cams[j]))
        if len(out) == n:
            break
    return out


def pixel_rays(cam):
    W, H = cam["width"], cam["height"]
    u = (np.arange(W) + 0.5 - cam["cx"]) / cam["fx"]
    v = (np.arange(H) + 0.5 - cam["cy"]) / cam["fy"]
    d = np.stack(np.broadcast_arrays(u[None, :], v[:, None], np.ones((H, W))), -1).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return d @ cam["R"].T  # world directions


def visibility(scene, a, b):
    W, H = b["width"], b["height"]
    dirs = pixel_rays(b)
    n = len(dirs)
    o = np.repeat(b["C"][None, :], n, axis=0)
    ray = mi.Ray3f(mi.Point3f(o.T.astype(np.float32)), mi.Vector3f(dirs.T.astype(np.float32)))
    si = scene.ray_intersect(ray)
    hit = np.array(si.is_valid())
    p = np.array(si.p).T.astype(np.float64)
    nrm = np.array(si.n).T.astype(np.float64)
    # Self-check: camera z of the hit against the stored depth of B.
    z_b = (p - b["C"]) @ b["R"][:, 2]
    stored = np.array(mi.Bitmap(os.path.join(SCENES, b["scene"], "depth", b["img_name"] + ".exr")))
    stored = stored.reshape(-1)
    ok = hit & (stored > 0)
    rel = np.abs(z_b[ok] - stored[ok]) / stored[ok]
    assert rel.max() < 1e-4, f"rebuilt scene differs from the stored depth: {rel.max()}"
    # Face A, project inside A, unoccluded.
    to_a = a["C"][None, :] - p
    dist = np.linalg.norm(to_a, axis=1)
    nrm = np.where(((nrm * (o - p)).sum(1) < 0)[:, None], -nrm, nrm)  # face B (two-sided)
    facing = (nrm * to_a).sum(1) > 0
    q = (p - a["C"]) @ a["R"]
    with np.errstate(divide="ignore", invalid="ignore"):
        ua = a["fx"] * q[:, 0] / q[:, 2] + a["cx"]
        va = a["fy"] * q[:, 1] / q[:, 2] + a["cy"]
    inside = (q[:, 2] > 0) & (ua >= 0) & (va >= 0) & (ua < a["width"]) & (va < a["height"])
    start = p + OFFSET * nrm
    d_a = a["C"][None, :] - start
    len_a = np.linalg.norm(d_a, axis=1)
    sray = mi.Ray3f(mi.Point3f(start.T.astype(np.float32)),
                    mi.Vector3f((d_a / len_a[:, None]).T.astype(np.float32)))
    sray.maxt = mi.Float((len_a * (1.0 - 1e-5)).astype(np.float32))
    occluded = np.array(scene.ray_test(sray))
    vis = hit & facing & inside & ~occluded
    del dist
    return vis.reshape(H, W)


def main():
    mi.set_variant("llvm_ad_rgb")
    dr.set_thread_count(2)
    meta = dict(tool=f"mitsuba {mi.__version__} llvm_ad_rgb (ray_intersect / ray_test)",
                generator="reference_data/generate/make_dibr_goldens.py",
                rule="visible = B's pixel-centre surface point faces A, projects inside A "
                     "(z > 0), and ray_test from p + 1e-4 n to A's centre finds nothing",
                pairs=[])
    for name in ("lounge", "gallery"):
        scene, _, _ = ms.build_scene(name)
        cams = cameras(name)
        for c in cams:
            c["scene"] = name
        for a, b in pick_pairs(cams, PAIRS_PER_SCENE):
            vis = visibility(scene, a, b)
            out = ensure_dir(os.path.join(OUT, name, f"{a['img_name']}__{b['img_name']}"))
            img = (vis.astype(np.uint8) * 255)[:, :, None]
            mi.Bitmap(img).write(os.path.join(out, "visible.png"))
            frac = float(vis.mean())
            meta["pairs"].append(dict(scene=name, source=a["img_name"], target=b["img_name"],
                                      distance=float(np.linalg.norm(a["C"] - b["C"])),
                                      visible_fraction=frac))
            print(name, a["img_name"], "->", b["img_name"], f"visible {frac:.3f}", flush=True)
    with open(os.path.join(OUT, "meta.json"), "w") as f:
        json.dump(meta, f, indent=1)


if __name__ == "__main__":
    main()
