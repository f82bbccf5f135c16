"""Synthetic indoor scenes with ground truth, rendered by Mitsuba 3 (issue #4, SPEC.md §14).

Two rooms (6 m x 2.8 m x 5 m, y up): `lounge` (textured walls and floor, many objects of
different materials and sizes) and `gallery` (large plain walls, a few objects, framed
pictures). Each has N_CAMS pinhole cameras inside the room at 160x120. Every camera looks
either towards -x (the `train` half) or towards +x (the `heldout` half), the paper's
ScanNet++ protocol: reconstruct one half, extrapolate into the other.

Written per scene, in unseen's dataset format (SPEC.md §14):
  cameras.json          INRIA cameras.json, world_from_camera in the OpenCV camera frame
  images/<name>.png     sRGB 8-bit, path traced (box pixel filter, SPP samples per pixel)
  depth/<name>.exr      camera-z depth at the pixel centre (float32, channel Y; 0 = no hit)
  points3D.ply          sparse coloured point cloud from the train cameras only
  split.json            {"train": [...], "heldout": [...]}
  meta.json             tool versions, settings

Run: DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 python make_scenes.py
"""
import json
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from common import ensure_dir, look_at, write_cameras_json, write_depth_exr  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

mi.set_variant("llvm_ad_rgb")
dr.set_thread_count(2)

OUT = os.path.join(os.path.dirname(__file__), "..", "scenes")
W, H = 160, 120
FOV_X_DEG = 70.0
N_CAMS = 72
SPP = 256
POINTS_PER_VIEW = 64
ROOM = dict(x=3.0, y=2.8, z=2.5)  # x in [-3, 3], y in [0, 2.8], z in [-2.5, 2.5]
T = mi.ScalarTransform4f


# ---------------------------------------------------------------- textures (seeded numpy)

def save_tex(tmp, name, img):
    path = os.path.join(tmp, name + ".png")
    mi.Bitmap(np.ascontiguousarray(img, np.float32)).convert(
        mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(path)
    return path


def smooth_noise(rng, n, cells):
    g = rng.uniform(0, 1, (cells + 1, cells + 1))
    t = np.linspace(0, cells, n, endpoint=False)
    i = t.astype(int)
    f = t - i
    f = f * f * (3 - 2 * f)
    a = g[i][:, i] * (1 - f)[None, :] + g[i][:, i + 1] * f[None, :]
    b = g[i + 1][:, i] * (1 - f)[None, :] + g[i + 1][:, i + 1] * f[None, :]
    return a * (1 - f)[:, None] + b * f[:, None]


def bricks(rng, n=512):
    img = np.zeros((n, n, 3))
    rows, cols = 16, 8
    bh, bw = n // rows, n // cols
    for r in range(rows):
        off = (bw // 2) * (r % 2)
        for c in range(-1, cols + 1):
            col = np.array([0.55, 0.25, 0.18]) * rng.uniform(0.75, 1.2)
            x0, x1 = max(c * bw + off, 0), min((c + 1) * bw + off, n)
            if x1 > x0:
                img[r * bh:(r + 1) * bh, x0:x1] = col
    mortar = np.zeros((n, n), bool)
    for r in range(rows):
        mortar[r * bh:r * bh + 3] = True
    for r in range(rows):
        off = (bw // 2) * (r % 2)
        for c in range(cols + 1):
            x = c * bw + off
            mortar[r * bh:(r + 1) * bh, max(x - 1, 0):min(x + 2, n)] = True
    img[mortar] = [0.7, 0.68, 0.62]
    return np.clip(img * (0.85 + 0.3 * smooth_noise(rng, n, 32))[..., None], 0, 1)


def wood(rng, n=512):
    y = np.linspace(0, 1, n)[:, None]
    x = np.linspace(0, 1, n)[None, :]
    grain = 0.5 + 0.5 * np.sin(60 * y + 6 * smooth_noise(rng, n, 8) + 2 * x)
    planks = (np.floor(x * 6) % 2) * 0.08
    base = np.array([0.45, 0.3, 0.16])
    return np.clip(base[None, None] * (0.75 + 0.35 * grain + planks)[..., None], 0, 1)


def stripes(rng, n=512, a=(0.75, 0.72, 0.55), b=(0.45, 0.55, 0.6)):
    x = np.linspace(0, 1, n)[None, :].repeat(n, 0)
    s = (np.floor(x * 20) % 2)[..., None]
    img = s * np.array(a) + (1 - s) * np.array(b)
    return np.clip(img * (0.9 + 0.2 * smooth_noise(rng, n, 16))[..., None], 0, 1)


def plaster(rng, n=512, col=(0.7, 0.72, 0.7)):
    v = 0.8 + 0.25 * smooth_noise(rng, n, 24) + 0.1 * smooth_noise(rng, n, 96)
    return np.clip(np.array(col)[None, None] * v[..., None], 0, 1)


def checker(n=512, k=8, a=(0.85, 0.85, 0.8), b=(0.1, 0.2, 0.45)):
    y, x = np.mgrid[0:n, 0:n] * k // n
    s = ((x + y) % 2)[..., None]
    return s * np.array(a) + (1 - s) * np.array(b)


def painting(rng, n=256):
    img = np.zeros((n, n, 3)) + rng.uniform(0.2, 0.9, 3)
    for _ in range(12):
        c = rng.uniform(0, 1, 3)
        x0, y0 = rng.integers(0, n - 20, 2)
        w, h = rng.integers(20, n // 2, 2)
        img[y0:y0 + h, x0:x0 + w] = c
    return img


# ---------------------------------------------------------------- scene construction

def diffuse_tex(path):
    return {"type": "diffuse", "reflectance": {"type": "bitmap", "filename": path}}


def diffuse(rgb):
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}


def room(walls, floor, ceiling):
    """Six inward-facing rectangles; walls = [back(-z), front(+z), left(-x), right(+x)]."""
    X, Y, Z = ROOM["x"], ROOM["y"], ROOM["z"]
    return {
        "floor": {"type": "rectangle", "bsdf": floor,
                  "to_world": T().translate([0, 0, 0]).rotate([1, 0, 0], -90).scale([X, Z, 1])},
        "ceiling": {"type": "rectangle", "bsdf": ceiling,
                    "to_world": T().translate([0, Y, 0]).rotate([1, 0, 0], 90).scale([X, Z, 1])},
        "wall_back": {"type": "rectangle", "bsdf": walls[0],
                      "to_world": T().translate([0, Y / 2, -Z]).scale([X, Y / 2, 1])},
        "wall_front": {"type": "rectangle", "bsdf": walls[1],
                       "to_world": T().translate([0, Y / 2, Z]).rotate([0, 1, 0], 180).scale([X, Y / 2, 1])},
        "wall_left": {"type": "rectangle", "bsdf": walls[2],
                      "to_world": T().translate([-X, Y / 2, 0]).rotate([0, 1, 0], 90).scale([Z, Y / 2, 1])},
        "wall_right": {"type": "rectangle", "bsdf": walls[3],
                       "to_world": T().translate([X, Y / 2, 0]).rotate([0, 1, 0], -90).scale([Z, Y / 2, 1])},
        "light_a": {"type": "rectangle", "to_world": T().translate([-1.5, Y - 0.01, 0]).rotate([1, 0, 0], 90).scale([0.6, 0.6, 1]),
                    "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [9.0, 8.6, 8.0]}}},
        "light_b": {"type": "rectangle", "to_world": T().translate([1.5, Y - 0.01, 0]).rotate([1, 0, 0], 90).scale([0.6, 0.6, 1]),
                    "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [8.0, 8.4, 9.0]}}},
    }


def box(center, half, bsdf, yaw=0.0):
    return {"type": "cube", "bsdf": bsdf,
            "to_world": T().translate(list(center)).rotate([0, 1, 0], yaw).scale(list(half))}, (center, half)


def sphere(center, r, bsdf):
    return {"type": "sphere", "center": list(center), "radius": r, "bsdf": bsdf}, (center, (r, r, r))


def cylinder(base, r, h, bsdf):
    shape = {"type": "cylinder", "p0": list(base), "p1": [base[0], base[1] + h, base[2]], "radius": r,
             "bsdf": bsdf}
    return shape, ((base[0], base[1] + h / 2, base[2]), (r, h / 2, r))


def lounge(tmp, rng):
    s = room([diffuse_tex(save_tex(tmp, "stripes", stripes(rng))),
              diffuse_tex(save_tex(tmp, "plaster", plaster(rng, col=(0.75, 0.7, 0.6)))),
              diffuse_tex(save_tex(tmp, "bricks", bricks(rng))),
              diffuse_tex(save_tex(tmp, "stripes2", stripes(rng, a=(0.8, 0.6, 0.6), b=(0.6, 0.7, 0.5))))],
             diffuse_tex(save_tex(tmp, "wood", wood(rng))),
             diffuse((0.8, 0.8, 0.78)))
    woodtex = diffuse_tex(save_tex(tmp, "wood2", wood(rng)))
    objs = [
        box((-1.6, 0.375, -0.8), (0.6, 0.375, 0.4), woodtex, yaw=15),                  # table, -x half
        sphere((-1.5, 0.95, -0.8), 0.2, {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.1, 0.1]}}),
        cylinder((-2.3, 0.0, 1.4), 0.25, 1.6, {"type": "roughconductor", "material": "Al", "alpha": 0.35}),
        box((-0.9, 0.25, 1.2), (0.25, 0.25, 0.25), diffuse_tex(save_tex(tmp, "checker", checker())), yaw=30),
        box((1.8, 0.4, -1.7), (0.9, 0.4, 0.45), diffuse((0.2, 0.35, 0.25))),            # sofa, +x half
        sphere((1.2, 0.15, 0.9), 0.15, diffuse((0.9, 0.75, 0.2))),
        sphere((1.5, 0.35, 1.5), 0.35, {"type": "roughplastic", "alpha": 0.2, "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.3, 0.7]}}),
        cylinder((2.4, 0.0, 0.6), 0.12, 1.1, diffuse((0.85, 0.85, 0.85))),
        box((0.0, 0.05, 0.0), (0.8, 0.05, 0.6), diffuse_tex(save_tex(tmp, "rug", checker(k=12, a=(0.6, 0.2, 0.2), b=(0.8, 0.7, 0.5))))),
    ]
    return s, objs


def gallery(tmp, rng):
    s = room([diffuse((0.82, 0.82, 0.8)), diffuse((0.6, 0.7, 0.8)),
              diffuse((0.85, 0.8, 0.7)), diffuse((0.7, 0.75, 0.7))],
             diffuse_tex(save_tex(tmp, "gplaster", plaster(rng, col=(0.5, 0.5, 0.52)))),
             diffuse((0.9, 0.9, 0.9)))
    X, Z = ROOM["x"], ROOM["z"]
    objs = [
        box((-1.2, 0.5, 0.3), (0.5, 0.5, 0.5), diffuse((0.9, 0.9, 0.88))),            # plinth
        sphere((-1.2, 1.3, 0.3), 0.3, {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.15, 0.5, 0.2]}}),
        box((1.5, 0.6, -0.5), (0.35, 0.6, 0.35), diffuse((0.3, 0.3, 0.35)), yaw=20),
        cylinder((1.0, 0.0, 1.3), 0.3, 0.8, diffuse((0.75, 0.45, 0.2))),
    ]
    pics = [((-X + 0.01, 1.5, -1.0), 90, (0.5, 0.4)), ((X - 0.01, 1.4, 0.8), -90, (0.6, 0.45)),
            ((-0.8, 1.5, -Z + 0.01), 0, (0.7, 0.5))]
    for k, (c, yaw, (hw, hh)) in enumerate(pics):
        p = save_tex(tmp, f"painting{k}", painting(rng))
        objs.append(({"type": "rectangle", "bsdf": diffuse_tex(p),
                      "to_world": T().translate(list(c)).rotate([0, 1, 0], yaw).scale([hw, hh, 1])}, None))
    return s, objs


# ---------------------------------------------------------------- cameras

def inside_any(p, boxes, margin=0.25):
    for b in boxes:
        if b is None:
            continue
        c, h = b
        if all(abs(p[i] - c[i]) < h[i] + margin for i in range(3)):
            return True
    return False


def make_cameras(rng, boxes):
    cams = []
    fx = 0.5 * W / np.tan(np.radians(FOV_X_DEG) / 2)
    i = 0
    while len(cams) < N_CAMS:
        side = -1.0 if len(cams) % 2 == 0 else 1.0  # even: train (-x), odd: heldout (+x)
        eye = np.array([rng.uniform(-2.3, 2.3), rng.uniform(0.8, 1.9), rng.uniform(-1.9, 1.9)])
        if inside_any(eye, boxes):
            continue
        target = np.array([side * rng.uniform(0.6, 3.0), rng.uniform(0.1, 1.6), rng.uniform(-2.4, 2.4)])
        d = target - eye
        if side * d[0] < 0.5 * np.linalg.norm(d) or np.linalg.norm(d) < 1.0:
            continue
        R = look_at(eye, target, (0, 1, 0))
        name = f"{'train' if side < 0 else 'heldout'}_{len(cams) // 2:03d}"
        cams.append(dict(name=name, width=W, height=H, fx=fx, fy=fx, cx=W / 2, cy=H / 2,
                         R_wc=R, center=eye))
        i += 1
    return cams


def sensor(cam, sampler):
    to_world = np.eye(4)
    to_world[:3, :3] = cam["R_wc"] @ np.diag([-1.0, -1.0, 1.0])  # Mitsuba camera: x left, y up
    to_world[:3, 3] = cam["center"]
    return mi.load_dict({
        "type": "perspective", "fov": FOV_X_DEG, "fov_axis": "x",
        "to_world": mi.ScalarTransform4f(to_world.tolist()),
        "near_clip": NEAR_CLIP, "far_clip": 100.0, "sampler": sampler,
        "film": {"type": "hdrfilm", "width": W, "height": H, "pixel_format": "rgb",
                 "rfilter": {"type": "box"}},
    })


NEAR_CLIP = 0.01


def ray_to_z(cam):
    """cos of the pixel-centre ray's angle to the optical axis. Mitsuba starts camera rays on
    the near plane (ray.o += d * near/cos), so its depth AOV is t - near/cos and the camera z
    is depth * cos + near (checked on a fronto-parallel wall: exact to f32)."""
    u = (np.arange(W) + 0.5 - cam["cx"]) / cam["fx"]
    v = (np.arange(H) + 0.5 - cam["cy"]) / cam["fy"]
    return 1.0 / np.sqrt(1.0 + u[None, :] ** 2 + v[:, None] ** 2)


def write_points_ply(path, xyz, rgb8):
    n = len(xyz)
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {n}\n"
              "property float x\nproperty float y\nproperty float z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                             ("r", "u1"), ("g", "u1"), ("b", "u1")])
    rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    rec["r"], rec["g"], rec["b"] = rgb8[:, 0], rgb8[:, 1], rgb8[:, 2]
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(rec.tobytes())


SEEDS = {"lounge": 11, "gallery": 12}


def build_scene(name):
    """The Mitsuba scene `name` (textures are loaded, so the temporary folder may go), its
    object boxes, and the generator positioned after the scene was built (the cameras come
    next). make_dibr_goldens.py and make_morph_goldens.py rebuild the scenes with it."""
    builder = {"lounge": lounge, "gallery": gallery}[name]
    rng = np.random.Generator(np.random.PCG64(SEEDS[name]))
    with tempfile.TemporaryDirectory() as tmp:
        shell, objs = builder(tmp, rng)
        d = {"type": "scene", **shell}
        for k, (shape, _) in enumerate(objs):
            d[f"obj{k}"] = shape
        scene = mi.load_dict(d)
    return scene, [b for _, b in objs], rng


def make_scene(name):
    scene, boxes, rng = build_scene(name)
    cams = make_cameras(rng, boxes)
    out = ensure_dir(os.path.join(OUT, name))
    ensure_dir(os.path.join(out, "images"))
    ensure_dir(os.path.join(out, "depth"))
    path_int = mi.load_dict({"type": "path", "max_depth": 5})
    depth_int = mi.load_dict({"type": "aov", "aovs": "dd.y:depth"})
    pts, cols = [], []
    for k, cam in enumerate(cams):
        img = mi.render(scene, sensor=sensor(cam, {"type": "independent", "sample_count": SPP}),
                        integrator=path_int, spp=SPP, seed=k)
        bmp = mi.Bitmap(img).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True)
        bmp.write(os.path.join(out, "images", cam["name"] + ".png"))
        dist = np.array(mi.render(scene, sensor=sensor(cam, {"type": "stratified", "sample_count": 1, "jitter": False}),
                                  integrator=depth_int, spp=1))[:, :, 0]
        hit = dist > 0
        z = np.where(hit, dist * ray_to_z(cam) + NEAR_CLIP, 0.0).astype(np.float32)
        write_depth_exr(os.path.join(out, "depth", cam["name"] + ".exr"), z)
        if cam["name"].startswith("train"):
            rgb8 = np.array(bmp)
            ys = rng.integers(0, H, POINTS_PER_VIEW)
            xs = rng.integers(0, W, POINTS_PER_VIEW)
            for y, x in zip(ys, xs):
                if z[y, x] <= 0:
                    continue
                pc = np.array([(x + 0.5 - cam["cx"]) / cam["fx"], (y + 0.5 - cam["cy"]) / cam["fy"], 1.0]) * z[y, x]
                pts.append(cam["R_wc"] @ pc + cam["center"])
                cols.append(rgb8[y, x])
        print(f"{name}: {k + 1}/{len(cams)} {cam['name']}", flush=True)
    write_cameras_json(os.path.join(out, "cameras.json"), cams)
    write_points_ply(os.path.join(out, "points3D.ply"), np.array(pts), np.array(cols, np.uint8))
    split = {"train": [c["name"] for c in cams if c["name"].startswith("train")],
             "heldout": [c["name"] for c in cams if c["name"].startswith("heldout")],
             "protocol": "train: cameras looking towards -x; heldout: towards +x (paper's ScanNet++ half-scene protocol)"}
    with open(os.path.join(out, "split.json"), "w") as f:
        json.dump(split, f, indent=1)
    with open(os.path.join(out, "meta.json"), "w") as f:
        json.dump(dict(scene=name, cameras=len(cams), width=W, height=H, fov_x_deg=FOV_X_DEG, spp=SPP,
                       seed=SEEDS[name], points=len(pts),
                       tool=f"mitsuba {mi.__version__} llvm_ad_rgb, path (max_depth 5), box filter; "
                            "depth: aov dd.y:depth at pixel centres converted to camera z",
                       generator="reference_data/generate/make_scenes.py"), f, indent=1)


def main():
    which = sys.argv[1:] or ["lounge", "gallery"]
    for name in ("lounge", "gallery"):
        if name in which:
            make_scene(name)


if __name__ == "__main__":
    main()
