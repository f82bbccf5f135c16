"""The bundled demo scene: a small room of Gaussians (floor, walls, objects), SH degree 1.

Writes reference_data/demo/scene.ply (INRIA layout) and cameras.json (INRIA layout,
8 cameras around the room at 320x240). Deterministic: numpy Generator(PCG64, seed 7).
Run: python make_demo_scene.py   (needs only numpy)
"""
import os

import numpy as np

from common import SH_C0, ensure_dir, look_at, write_cameras_json, write_inria_ply

rng = np.random.Generator(np.random.PCG64(7))
means, scales, quats, opac, rgb = [], [], [], [], []


def add(m, s, q, o, c):
    means.append(m), scales.append(s), quats.append(q), opac.append(o), rgb.append(c)


def flat_patch_grid(origin, u, v, nu, nv, thickness, color_fn):
    """Flat Gaussians tiling a rectangle origin + a*u + b*v, a, b in [0, 1]."""
    u, v = np.asarray(u, float), np.asarray(v, float)
    normal = np.cross(u, v)
    normal /= np.linalg.norm(normal)
    su, sv = np.linalg.norm(u) / nu, np.linalg.norm(v) / nv
    rot = np.stack([u / np.linalg.norm(u), v / np.linalg.norm(v), normal], axis=1)
    q = rot_to_quat(rot)
    for i in range(nu):
        for j in range(nv):
            a, b = (i + 0.5) / nu, (j + 0.5) / nv
            p = origin + a * u + b * v + rng.normal(0, 0.003, 3)
            add(p, [0.6 * su, 0.6 * sv, thickness], q, 0.95, color_fn(a, b))


def rot_to_quat(r):
    w = np.sqrt(max(1e-12, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = (r[2, 1] - r[1, 2]) / (4 * w)
    y = (r[0, 2] - r[2, 0]) / (4 * w)
    z = (r[1, 0] - r[0, 1]) / (4 * w)
    return np.array([w, x, y, z])


def checker(c1, c2, n):
    return lambda a, b: c1 if (int(a * n) + int(b * n)) % 2 == 0 else c2


# Room: floor y = 1 (world +y down, like the camera frame), walls at x = +-2, z = 3.
flat_patch_grid(np.array([-2.0, 1.0, -2.0]), [4, 0, 0], [0, 0, 5], 40, 50, 0.004,
                checker(np.array([0.85, 0.8, 0.7]), np.array([0.35, 0.3, 0.28]), 8))
flat_patch_grid(np.array([-2.0, -1.5, 3.0]), [4, 0, 0], [0, 2.5, 0], 40, 25, 0.004,
                lambda a, b: np.array([0.3 + 0.5 * a, 0.45, 0.7 - 0.3 * b]))
flat_patch_grid(np.array([-2.0, -1.5, -2.0]), [0, 0, 5], [0, 2.5, 0], 50, 25, 0.004,
                lambda a, b: np.array([0.75, 0.72, 0.6]) * (0.8 + 0.2 * np.sin(12 * a)))
flat_patch_grid(np.array([2.0, -1.5, -2.0]), [0, 0, 5], [0, 2.5, 0], 50, 25, 0.004,
                lambda a, b: np.array([0.55, 0.7, 0.55]))

# Objects: three blobby spheres of small Gaussians.
for centre, radius, colour in [((-0.8, 0.55, 1.2), 0.45, (0.9, 0.2, 0.15)),
                               ((0.7, 0.65, 1.8), 0.35, (0.15, 0.35, 0.9)),
                               ((0.1, 0.75, 0.4), 0.25, (0.95, 0.8, 0.2))]:
    n = int(1500 * radius)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for k in range(n):
        q = rng.normal(size=4)
        shade = 0.75 + 0.25 * (-d[k, 1])
        add(np.array(centre) + radius * d[k], [0.06 * radius] * 3 + rng.uniform(0, 0.02, 3),
            q / np.linalg.norm(q), 0.9, np.array(colour) * shade)

means = np.array(means)
n = len(means)
log_scales = np.log(np.array(scales))
quats = np.array(quats)
opacity_logits = np.log(np.array(opac) / (1 - np.array(opac)))
sh_dc = (np.array(rgb) - 0.5) / SH_C0
sh_rest = rng.normal(0, 0.03, size=(n, 3, 3))  # degree 1: mild view dependence

out = ensure_dir(os.path.join(os.path.dirname(__file__), "..", "demo"))
write_inria_ply(os.path.join(out, "scene.ply"), means, log_scales, quats, opacity_logits,
                sh_dc, sh_rest)
cams = []
for i in range(8):
    ang = -0.9 + 1.8 * i / 7
    eye = np.array([2.2 * np.sin(ang), -0.2, -2.5 + 0.8 * np.cos(ang)])
    target = np.array([0.0, 0.5, 1.5])
    fx = 0.5 * 320 / np.tan(np.radians(70) / 2)
    cams.append(dict(name=f"view_{i:02d}", width=320, height=240, fx=fx, fy=fx,
                     R_wc=look_at(eye, target, [0, -1, 0]), center=eye))
write_cameras_json(os.path.join(out, "cameras.json"), cams)
print(f"wrote {n} Gaussians and {len(cams)} cameras to {os.path.normpath(out)}")
