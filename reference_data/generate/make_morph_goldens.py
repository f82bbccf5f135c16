"""Mitsuba renders at interpolated poses for the `morph` video test (issue #7, SPEC.md §19.3).

For the nearby camera pair lounge heldout_025 -> heldout_033 (also a DIBR pair), the camera
at t = k/(N-1), k = 1..N-2 (N = 5): rotation by slerp of the unit quaternions (shortest
arc), centre by linear interpolation (the convention unseen's `interpolate_camera`
documents); rendered like the bundled scene (make_scenes.py: path tracer, 256 spp, box
filter). Written to reference_data/mitsuba/morph/<A>__<B>/: frame_<k>.png (sRGB 8-bit) and
cameras.json (the interpolated cameras, INRIA layout).

Run: DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 python make_morph_goldens.py
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
import make_scenes as ms  # noqa: E402
from common import ensure_dir, write_cameras_json  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

HERE = os.path.dirname(__file__)
PAIR = ("heldout_025", "heldout_033")
N = 5


def quat(R):
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    t = np.trace(R)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k]) * 2
        q = [0.0] * 4
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q = np.array(q)
    return q / np.linalg.norm(q)


def rot(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def slerp(a, b, t):
    if a @ b < 0:
        b = -b
    th = np.arccos(min(1.0, a @ b))
    s = np.sin(th)
    if s < 1e-9:
        q = a * (1 - t) + b * t
    else:
        q = a * np.sin((1 - t) * th) / s + b * np.sin(t * th) / s
    return q / np.linalg.norm(q)


def main():
    mi.set_variant("llvm_ad_rgb")
    dr.set_thread_count(2)
    with open(os.path.join(HERE, "..", "scenes", "lounge", "cameras.json")) as f:
        cams = {c["img_name"]: c for c in json.load(f)}
    a, b = cams[PAIR[0]], cams[PAIR[1]]
    scene, _, _ = ms.build_scene("lounge")
    out = ensure_dir(os.path.join(HERE, "..", "mitsuba", "morph", f"{PAIR[0]}__{PAIR[1]}"))
    qa, qb = quat(np.array(a["rotation"])), quat(np.array(b["rotation"]))
    frames = []
    path_int = mi.load_dict({"type": "path", "max_depth": 5})
    for k in range(1, N - 1):
        t = k / (N - 1)
        R = rot(slerp(qa, qb, t))
        C = np.array(a["position"]) * (1 - t) + np.array(b["position"]) * t
        cam = dict(name=f"frame_{k}", width=a["width"], height=a["height"], fx=a["fx"], fy=a["fy"],
                   cx=a["cx"], cy=a["cy"], R_wc=R, center=C)
        img = mi.render(scene, sensor=ms.sensor(cam, {"type": "independent", "sample_count": ms.SPP}),
                        integrator=path_int, spp=ms.SPP, seed=1000 + k)
        mi.Bitmap(img).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(
            os.path.join(out, f"frame_{k}.png"))
        frames.append(cam)
        print("rendered", cam["name"], flush=True)
    write_cameras_json(os.path.join(out, "cameras.json"), frames)
    with open(os.path.join(out, "meta.json"), "w") as f:
        json.dump(dict(pair=PAIR, n=N, tool=f"mitsuba {mi.__version__} llvm_ad_rgb, path max_depth 5, {ms.SPP} spp",
                       generator="reference_data/generate/make_morph_goldens.py"), f, indent=1)


if __name__ == "__main__":
    main()
