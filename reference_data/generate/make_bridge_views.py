"""Bridge views for the synthetic rooms of make_scenes.py.

The `train` cameras of each room look towards -x and the `heldout` cameras towards +x; the
halves share little visible surface (measured with the test below: mean co-visible
fraction of a held-out view 0.13 in lounge, 0.33 in gallery; 6 and 2 held-out views see
none). A bridge view looks sideways to moderately +x, so it sees part of what the train
cameras saw and part of the unseen (+x) half: candidate views for an extrapolation
pipeline (SPEC.md §14.5, §20.7).

Per room (the scene is rebuilt with make_scenes.build_scene, nothing existing changes):
  - cameras are proposed like make_scenes.make_cameras (same eye box, not inside an object,
    look_at with up (0, 1, 0), same intrinsics), from a NEW generator
    PCG64(1000 + SEEDS[name]), with a viewing direction whose x-component is between
    -0.2 and +0.7 of its length and a target at least 1 m away;
  - each proposal's depth is rendered first (same AOV and camera-z conversion as
    make_scenes.py) and its co-visible fraction measured: the fraction of its W*H pixels
    whose surface point (pixel centre unprojected with its camera-z depth) lands inside
    some train camera's image with |z_train(pixel) - z_point| <= 0.02 z_point (pixels with
    no hit count as not co-visible);
  - a proposal is kept if that fraction is in COVISIBLE_RANGE, until N_BRIDGE are kept,
    named bridge_000.. in acceptance order;
  - kept cameras are rendered like make_scenes.py (path, max_depth 5, independent sampler,
    SPP, seed 1000 + k) into images/bridge_XXX.png, depth into depth/bridge_XXX.exr;
  - cameras.json gets the new cameras appended (existing entries byte-identical),
    split.json a "bridge" list, meta.json the bridge_* keys.

Run: DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 python make_bridge_views.py [lounge] [gallery]
"""
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from common import camera_entry, ensure_dir, look_at, write_depth_exr  # noqa: E402
from make_scenes import (FOV_X_DEG, H, NEAR_CLIP, OUT, SEEDS, SPP, W, build_scene,  # noqa: E402
                         inside_any, ray_to_z, sensor)

import mitsuba as mi  # noqa: E402  (variant and thread count set by make_scenes)

N_BRIDGE = 24
COVISIBLE_RANGE = (0.15, 0.60)
DEPTH_REL_TOL = 0.02
X_FRACTION = (-0.2, 0.7)  # x-component of the viewing direction over its length
MAX_PROPOSALS = 2000


def read_depth(path):
    z = np.array(mi.Bitmap(path), dtype=np.float32)
    return z[:, :, 0] if z.ndim == 3 else z


def render_depth(scene, cam):
    """Camera-z depth at pixel centres, exactly as make_scenes.make_scene computes it."""
    depth_int = mi.load_dict({"type": "aov", "aovs": "dd.y:depth"})
    dist = np.array(mi.render(scene, sensor=sensor(cam, {"type": "stratified", "sample_count": 1, "jitter": False}),
                              integrator=depth_int, spp=1))[:, :, 0]
    hit = dist > 0
    return np.where(hit, dist * ray_to_z(cam) + NEAR_CLIP, 0.0).astype(np.float32)


def cam_from_json(e):
    return dict(name=e["img_name"], width=e["width"], height=e["height"], fx=e["fx"], fy=e["fy"],
                cx=e.get("cx", e["width"] / 2), cy=e.get("cy", e["height"] / 2),
                R_wc=np.array(e["rotation"], dtype=np.float64), center=np.array(e["position"], dtype=np.float64))


def unproject(cam, z):
    """World points of the pixels with z > 0 (pixel (x, y) centre at (x + 0.5, y + 0.5);
    camera frame x right, y down, z forward) and their flat indices."""
    ys, xs = np.nonzero(z > 0)
    d = z[ys, xs].astype(np.float64)
    p = np.stack([(xs + 0.5 - cam["cx"]) / cam["fx"] * d, (ys + 0.5 - cam["cy"]) / cam["fy"] * d, d], axis=1)
    return p @ cam["R_wc"].T + cam["center"], ys * W + xs


def covisible_fraction(cam, z, train):
    """Fraction of cam's W*H pixels whose surface point some train camera also sees."""
    pts, idx = unproject(cam, z)
    seen = np.zeros(len(pts), bool)
    for tc, tz in train:
        pc = (pts - tc["center"]) @ tc["R_wc"]  # = R_wc^T (X - c), row-wise
        zc = pc[:, 2]
        ok = zc > NEAR_CLIP
        with np.errstate(divide="ignore", invalid="ignore"):
            u = tc["fx"] * pc[:, 0] / zc + tc["cx"]
            v = tc["fy"] * pc[:, 1] / zc + tc["cy"]
        ok &= (u >= 0) & (u < tc["width"]) & (v >= 0) & (v < tc["height"])
        ui = np.where(ok, np.floor(u), 0).astype(int)
        vi = np.where(ok, np.floor(v), 0).astype(int)
        zt = tz[vi, ui].astype(np.float64)
        ok &= (zt > 0) & (np.abs(zt - zc) <= DEPTH_REL_TOL * zc)
        seen |= ok
    return seen.sum() / float(W * H), idx


def propose(rng, boxes, fx):
    while True:
        eye = np.array([rng.uniform(-2.3, 2.3), rng.uniform(0.8, 1.9), rng.uniform(-1.9, 1.9)])
        if inside_any(eye, boxes):
            continue
        a = rng.uniform(*X_FRACTION)               # x-part of the horizontal unit direction
        side = 1.0 if rng.uniform() < 0.5 else -1.0
        r = rng.uniform(1.0, 3.0)                  # horizontal distance to the target
        ty = rng.uniform(0.1, 1.6)                 # target height, as make_cameras
        d = np.array([a * r, ty - eye[1], side * np.sqrt(1.0 - a * a) * r])
        n = np.linalg.norm(d)
        if n < 1.0 or not (X_FRACTION[0] * n <= d[0] <= X_FRACTION[1] * n):
            continue
        R = look_at(eye, eye + d, (0, 1, 0))
        return dict(width=W, height=H, fx=fx, fy=fx, cx=W / 2, cy=H / 2, R_wc=R, center=eye)


def dump_like(path, obj):
    """Write obj with make_scenes/common's formatting (json.dump, indent=1, no newline)."""
    text = json.dumps(obj, indent=1)
    with open(path, "w") as f:
        f.write(text)
    return text


def load_checked(path):
    with open(path) as f:
        text = f.read()
    obj = json.loads(text)
    assert json.dumps(obj, indent=1) == text, f"{path}: json round trip is not byte-identical"
    return obj, text


def make_bridges(name):
    t0 = time.time()
    out = os.path.join(OUT, name)
    scene, boxes, _ = build_scene(name)
    rng = np.random.Generator(np.random.PCG64(1000 + SEEDS[name]))
    fx = 0.5 * W / np.tan(np.radians(FOV_X_DEG) / 2)

    cams_path = os.path.join(out, "cameras.json")
    entries, _ = load_checked(cams_path)
    entries = [e for e in entries if not e["img_name"].startswith("bridge_")]  # re-runnable
    base_text = json.dumps(entries, indent=1)
    train = [(cam_from_json(e), read_depth(os.path.join(out, "depth", e["img_name"] + ".exr")))
             for e in entries if e["img_name"].startswith("train_")]
    assert train and all(abs(c["fx"] - fx) < 1e-9 for c, _ in train)

    # The rebuilt scene must be the one the stored depths came from.
    # (Re-rendering differs from the stored depths by up to ~3e-5 relative on some pixels:
    # float rounding of the JIT-compiled kernels, not geometry.)
    z0 = render_depth(scene, train[0][0])
    err = (np.abs(z0 - train[0][1]) / np.maximum(train[0][1], 1e-3)).max()
    assert err < 1e-4, f"{name}: re-rendered {train[0][0]['name']} depth differs by {err} (relative)"
    # A train view is fully co-visible with the train set (checks unproject/project agree).
    self_frac, _ = covisible_fraction(train[0][0], train[0][1], train)
    print(f"{name}: scene check ok (depth rel. err {err:.2e}, train_000 self co-visible {self_frac:.3f})", flush=True)

    ensure_dir(os.path.join(out, "images"))
    ensure_dir(os.path.join(out, "depth"))
    path_int = mi.load_dict({"type": "path", "max_depth": 5})
    kept, fracs, proposals = [], [], 0
    while len(kept) < N_BRIDGE:
        proposals += 1
        assert proposals <= MAX_PROPOSALS, f"{name}: only {len(kept)} bridge views in {MAX_PROPOSALS} proposals"
        cam = propose(rng, boxes, fx)
        z = render_depth(scene, cam)
        frac, _ = covisible_fraction(cam, z, train)
        if not (COVISIBLE_RANGE[0] <= frac <= COVISIBLE_RANGE[1]):
            print(f"{name}: proposal {proposals} co-visible {frac:.3f}: rejected", flush=True)
            continue
        k = len(kept)
        cam["name"] = f"bridge_{k:03d}"
        img = mi.render(scene, sensor=sensor(cam, {"type": "independent", "sample_count": SPP}),
                        integrator=path_int, spp=SPP, seed=1000 + k)
        mi.Bitmap(img).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(
            os.path.join(out, "images", cam["name"] + ".png"))
        write_depth_exr(os.path.join(out, "depth", cam["name"] + ".exr"), z)
        kept.append(cam)
        fracs.append(frac)
        print(f"{name}: proposal {proposals} co-visible {frac:.3f}: {cam['name']} "
              f"({k + 1}/{N_BRIDGE}, {time.time() - t0:.0f} s)", flush=True)

    # cameras.json: same keys, order and formatting as common.write_cameras_json.
    next_id = max(e["id"] for e in entries) + 1
    for k, c in enumerate(kept):
        entries.append(camera_entry(next_id + k, c))
    new_text = dump_like(cams_path, entries)
    assert base_text.endswith("\n]") and new_text.startswith(base_text[:-2] + ",\n"), "existing entries changed"

    split_path = os.path.join(out, "split.json")
    split, _ = load_checked(split_path)
    split["bridge"] = [c["name"] for c in kept]
    dump_like(split_path, split)

    meta_path = os.path.join(out, "meta.json")
    meta, _ = load_checked(meta_path)
    meta["bridge_cameras"] = N_BRIDGE
    meta["bridge_generator"] = "reference_data/generate/make_bridge_views.py"
    meta["bridge_covisible_range"] = list(COVISIBLE_RANGE)
    meta["bridge_covisible"] = [round(float(f), 3) for f in fracs]
    dump_like(meta_path, meta)
    print(f"{name}: {N_BRIDGE} bridge views from {proposals} proposals in {time.time() - t0:.0f} s; "
          f"co-visible {[round(float(f), 3) for f in fracs]}", flush=True)


def main():
    which = sys.argv[1:] or ["lounge", "gallery"]
    for name in ("lounge", "gallery"):
        if name in which:
            make_bridges(name)


if __name__ == "__main__":
    main()
