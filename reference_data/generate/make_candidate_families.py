"""Candidate families for the audit (SPEC.md §20.7, issue #54): other sets of candidate
poses than the bundled bridge views, so that a verdict can say which family it holds for.

The bundled candidates (candidates.json, make_extrapolation_split.py) are bridge views kept
because each sees 15-60 % of surface the train half saw. A user does not pick views that
way. Per room, this writes families that are not filtered by co-visibility:

  ring-7, ring-13  a ring of outward-facing views into the unseen (+x) half: eyes on a
                   horizontal circle of RING_RADIUS around the room's centre at RING_HEIGHT,
                   each looking radially outward, RING_PITCH_DEG down, at azimuths from -90
                   to +90 degrees about +x (13 views 15 degrees apart; ring-7 is every
                   other one, 30 degrees apart, the same images). An eye inside an object
                   (make_scenes.inside_any) moves to the first free radius of
                   RING_RADIUS_FALLBACK.
  walk-0, walk-1   random user-like sets: a person with a camera starts where a random
                   train camera stood and walks WALK_VIEWS steps of WALK_STEP metres,
                   heading first towards +x (within +-45 degrees), turning by
                   N(0, WALK_TURN_DEG) per step (re-drawn while the next eye would leave the
                   eye box of make_scenes.make_cameras or enter an object), eye height
                   N(1.45, 0.1) clipped to the eye box, looking along the heading turned by
                   N(0, WALK_LOOK_DEG) and pitched N(-10, 8) degrees; one view per step.
                   Generator PCG64(2000 + 10 * SEEDS[room] + k) for walk-k.

Every view is rendered like the scene's cameras (make_scenes.py: path tracer, max_depth 5,
SPP samples, box filter; depth as the camera-z AOV) into images/<name>.png and
depth/<name>.exr; names ring_NNN, walk0_NNN, walk1_NNN. Each family is an INRIA
cameras.json in families/<family>.json (what `unseen audit --candidates FAMILY` reads);
families/meta.json records the settings and each view's co-visible fraction (measured as
make_bridge_views.covisible_fraction does). Nothing that exists changes: the dataset's
top-level files, and so its digest, stay as they are.

Run: DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 python make_candidate_families.py [lounge] [gallery]
"""
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from common import camera_entry, ensure_dir, look_at, write_depth_exr  # noqa: E402
from make_bridge_views import cam_from_json, covisible_fraction, load_checked, read_depth, render_depth  # noqa: E402
from make_scenes import FOV_X_DEG, H, OUT, SEEDS, SPP, W, build_scene, inside_any, sensor  # noqa: E402

import mitsuba as mi  # noqa: E402  (variant and thread count set by make_scenes)

RING_RADIUS = 0.8
RING_RADIUS_FALLBACK = (0.6, 1.0, 0.4, 1.2)
RING_HEIGHT = 1.4
RING_PITCH_DEG = 10.0
RING_AZIMUTHS_DEG = [-90.0 + 15.0 * k for k in range(13)]
EYE_BOX = ((-2.3, 2.3), (0.8, 1.9), (-1.9, 1.9))  # make_scenes.make_cameras
WALK_VIEWS = 10
WALK_STEP = 0.3
WALK_TURN_DEG = 25.0
WALK_LOOK_DEG = 30.0
WALKS = 2
RENDER_SEED_BASE = 3000  # the path tracer's seed of view k of a room's families: 3000 + k


def direction(azimuth_deg, pitch_deg):
    """Unit vector at `azimuth` about +x towards +z, pitched down by `pitch` (y up)."""
    a, p = np.radians(azimuth_deg), np.radians(pitch_deg)
    return np.array([np.cos(a) * np.cos(p), -np.sin(p), np.sin(a) * np.cos(p)])


def camera(eye, d, fx):
    return dict(width=W, height=H, fx=fx, fy=fx, cx=W / 2, cy=H / 2,
                R_wc=look_at(eye, eye + d, (0, 1, 0)), center=np.asarray(eye, dtype=np.float64))


def in_box(eye):
    return all(lo <= eye[i] <= hi for i, (lo, hi) in enumerate(EYE_BOX))


def ring(boxes, fx):
    cams = []
    for k, az in enumerate(RING_AZIMUTHS_DEG):
        for r in (RING_RADIUS,) + RING_RADIUS_FALLBACK:
            eye = np.array([r * np.cos(np.radians(az)), RING_HEIGHT, r * np.sin(np.radians(az))])
            if not inside_any(eye, boxes):
                break
        else:
            raise AssertionError(f"ring view {k}: no free radius")
        c = camera(eye, direction(az, RING_PITCH_DEG), fx)
        c["name"] = f"ring_{k:03d}"
        c["radius"] = r
        cams.append(c)
    return cams


def walk(room, k, boxes, fx, train_eyes):
    rng = np.random.Generator(np.random.PCG64(2000 + 10 * SEEDS[room] + k))
    eye = train_eyes[rng.integers(len(train_eyes))].copy()
    heading = rng.uniform(-45.0, 45.0)
    cams = []
    while len(cams) < WALK_VIEWS:
        for _ in range(1000):
            h = heading + rng.normal(0.0, WALK_TURN_DEG)
            step = WALK_STEP * np.array([np.cos(np.radians(h)), 0.0, np.sin(np.radians(h))])
            nxt = eye + step
            nxt[1] = np.clip(rng.normal(1.45, 0.1), *EYE_BOX[1])
            if in_box(nxt) and not inside_any(nxt, boxes):
                break
        else:
            raise AssertionError(f"walk-{k}: stuck at {eye}")
        eye, heading = nxt, h
        look = heading + rng.normal(0.0, WALK_LOOK_DEG)
        pitch = rng.normal(10.0, 8.0)
        c = camera(eye, direction(look, pitch), fx)
        c["name"] = f"walk{k}_{len(cams):03d}"
        cams.append(c)
    return cams


def write_json(path, obj):
    with open(path, "w") as f:
        json.dump(obj, f, indent=1)
        f.write("\n")


def make_families(room):
    t0 = time.time()
    out = os.path.join(OUT, room)
    scene, boxes, _ = build_scene(room)
    fx = 0.5 * W / np.tan(np.radians(FOV_X_DEG) / 2)
    entries, _ = load_checked(os.path.join(out, "cameras.json"))
    train = [(cam_from_json(e), read_depth(os.path.join(out, "depth", e["img_name"] + ".exr")))
             for e in entries if e["img_name"].startswith("train_")]
    train_eyes = [c["center"] for c, _ in train]
    next_id = max(e["id"] for e in entries) + 1

    rings = ring(boxes, fx)
    walks = [walk(room, k, boxes, fx, train_eyes) for k in range(WALKS)]
    views = rings + [c for w in walks for c in w]
    families = {"ring-13": rings, "ring-7": rings[::2]}
    families.update({f"walk-{k}": w for k, w in enumerate(walks)})

    ensure_dir(os.path.join(out, "images"))
    ensure_dir(os.path.join(out, "depth"))
    ensure_dir(os.path.join(out, "families"))
    path_int = mi.load_dict({"type": "path", "max_depth": 5})
    covisible, ids = {}, {}
    for k, cam in enumerate(views):
        z = render_depth(scene, cam)
        frac, _ = covisible_fraction(cam, z, train)
        img = mi.render(scene, sensor=sensor(cam, {"type": "independent", "sample_count": SPP}),
                        integrator=path_int, spp=SPP, seed=RENDER_SEED_BASE + k)
        mi.Bitmap(img).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(
            os.path.join(out, "images", cam["name"] + ".png"))
        write_depth_exr(os.path.join(out, "depth", cam["name"] + ".exr"), z)
        covisible[cam["name"]] = round(float(frac), 3)
        ids[cam["name"]] = next_id + k
        print(f"{room}: {cam['name']} co-visible {frac:.3f} ({k + 1}/{len(views)}, {time.time() - t0:.0f} s)",
              flush=True)

    for name, cams in families.items():
        write_json(os.path.join(out, "families", name + ".json"), [camera_entry(ids[c["name"]], c) for c in cams])
    meta = {
        "generator": "reference_data/generate/make_candidate_families.py",
        "tool": f"mitsuba {mi.__version__} {mi.variant()}, path (max_depth 5), box filter, {SPP} spp; "
                "depth: aov dd.y:depth at pixel centres converted to camera z",
        "ring": {"radius": RING_RADIUS, "radius_fallback": list(RING_RADIUS_FALLBACK), "height": RING_HEIGHT,
                 "pitch_deg": RING_PITCH_DEG, "azimuths_deg": RING_AZIMUTHS_DEG,
                 "radii": [c["radius"] for c in rings]},
        "walk": {"views": WALK_VIEWS, "step": WALK_STEP, "turn_deg": WALK_TURN_DEG, "look_deg": WALK_LOOK_DEG,
                 "seeds": [2000 + 10 * SEEDS[room] + k for k in range(WALKS)]},
        "families": {name: [c["name"] for c in cams] for name, cams in families.items()},
        "covisible": covisible,
    }
    write_json(os.path.join(out, "families", "meta.json"), meta)
    print(f"{room}: {len(views)} views in {time.time() - t0:.0f} s", flush=True)


def main():
    which = sys.argv[1:] or ["lounge", "gallery"]
    for name in ("lounge", "gallery"):
        if name in which:
            make_families(name)


if __name__ == "__main__":
    main()
