"""COLMAP sparse models written by COLMAP itself (pycolmap), text and binary, plus the
expected cameras computed by pycolmap (world_from_camera rotation, centre, intrinsics).

Writes reference_data/colmap/<case>/{sparse_txt/, sparse_bin/, expected.json}.
Run: python make_colmap_goldens.py   (needs pycolmap, numpy)
"""
import json
import os
import shutil

import numpy as np
import pycolmap

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.normpath(os.path.join(HERE, "..", "colmap"))


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return pycolmap.Rotation3d(q[[1, 2, 3, 0]])  # xyzw


def build(rng, models):
    rec = pycolmap.Reconstruction()
    for cid, (model, params) in enumerate(models, start=1):
        cam = pycolmap.Camera(model=model, width=160 + 8 * cid, height=120 + 4 * cid,
                              params=params, camera_id=cid)
        rec.add_camera_with_trivial_rig(cam)
    iid = 1
    for cid in range(1, len(models) + 1):
        for k in range(3):
            img = pycolmap.Image(name=f"img_{cid}_{k}.png", camera_id=cid, image_id=iid)
            pose = pycolmap.Rigid3d(random_rotation(rng), rng.normal(size=3))
            rec.add_image_with_trivial_frame(img, pose)
            iid += 1
    for p in range(20):
        rec.add_point3D(rng.normal(size=3), pycolmap.Track(),
                        rng.integers(0, 256, 3).astype(np.uint8))
    return rec


def write_case(name, rec):
    d = os.path.join(OUT, name)
    shutil.rmtree(d, ignore_errors=True)
    for sub in ("sparse_txt", "sparse_bin"):
        os.makedirs(os.path.join(d, sub))
    rec.write_text(os.path.join(d, "sparse_txt"))
    rec.write_binary(os.path.join(d, "sparse_bin"))
    expected = []
    for _, img in sorted(rec.images.items(), key=lambda kv: kv[1].name):
        cam = rec.cameras[img.camera_id]
        R_cw = img.cam_from_world().rotation.matrix()
        expected.append(dict(
            name=img.name, width=cam.width, height=cam.height,
            fx=cam.focal_length_x, fy=cam.focal_length_y,
            cx=cam.principal_point_x, cy=cam.principal_point_y,
            world_from_camera=R_cw.T.tolist(), center=img.projection_center().tolist()))
    points = [dict(xyz=p.xyz.tolist(), rgb=p.color.tolist()) for _, p in sorted(rec.points3D.items())]
    with open(os.path.join(d, "expected.json"), "w") as f:
        json.dump(dict(tool=f"pycolmap {pycolmap.__version__}", cameras=expected, points=points), f,
                  indent=1)
    print(f"{name}: {len(expected)} images, {len(points)} points")


def main():
    rng = np.random.Generator(np.random.PCG64(5))
    write_case("pinhole", build(rng, [("PINHOLE", [150.0, 152.5, 81.3, 60.7]),
                                      ("SIMPLE_PINHOLE", [140.0, 84.0, 62.0])]))
    write_case("distorted", build(rng, [("OPENCV", [150.0, 150.0, 80.0, 60.0, 0.1, -0.05, 0.001, 0.0])]))


if __name__ == "__main__":
    main()
