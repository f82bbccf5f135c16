"""Mitsuba 3 cross-check of the splatting rasterizer: the same Gaussians ray traced by
Mitsuba's `ellipsoids` shape and `volprim_rf_basic` integrator (LLVM, float32).

Ray tracing evaluates each Gaussian's peak density along the pixel ray; splatting evaluates
the affine-projected 2D Gaussian (plus a 0.3 px^2 dilation) at the pixel centre. The two
agree closely only for Gaussians that are small against their distance and near the optical
axis, so the scene is a sparse grid of such Gaussians (screen sigma 4-10 px, few overlaps,
opacity <= 0.85 so neither 0.99 nor Mitsuba's 0.9999 clamp and neither T-stop applies).

Writes reference_data/mitsuba/ellipsoids/<case>/ {scene.ply, cameras.json, rgb.exr, meta.json}.
Run:  DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 python make_mitsuba_crosscheck.py
"""
import json
import os

import drjit as dr
import mitsuba as mi
import numpy as np

from common import SH_C0, ensure_dir, look_at, write_cameras_json, write_exr, write_inria_ply

mi.set_variant("llvm_ad_rgb")
dr.set_thread_count(2)  # a one-thread process deadlocks in OpenEXR (seen with Mitsuba 3.9.1 / Dr.Jit 1.5.0 on these machines)

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.normpath(os.path.join(HERE, "..", "mitsuba", "ellipsoids"))
W, H, FOV_X_DEG = 160, 120, 40.0


def quat_from_matrix_wxyz(r):
    w = np.sqrt(max(1e-12, 1 + np.trace(r))) / 2
    return np.array([w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w),
                     (r[1, 0] - r[0, 1]) / (4 * w)])


def make_case(name, rng, sh_degree, eye, target, up):
    R_wc = look_at(eye, target, up)  # world_from_camera, OpenCV frame
    eye = np.asarray(eye, float)
    # Gaussians on a jittered 4x3 grid in the camera's view, depths 3..5.
    pts_cam = []
    for i in range(4):
        for j in range(3):
            z = rng.uniform(3.0, 5.0)
            u = (-0.27 + 0.18 * i + rng.uniform(-0.02, 0.02)) * z
            v = (-0.16 + 0.16 * j + rng.uniform(-0.02, 0.02)) * z
            pts_cam.append([u, v, z])
    pts_cam = np.array(pts_cam)
    n = len(pts_cam)
    means = eye + pts_cam @ R_wc.T
    scales = rng.uniform(0.04, 0.09, (n, 3)) * (pts_cam[:, 2:3] / 4.0)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    opac = rng.uniform(0.3, 0.85, n)
    k = (sh_degree + 1) ** 2
    rgb = rng.uniform(0.1, 0.9, (n, 3))
    sh_dc = (rgb - 0.5) / SH_C0
    sh_rest = rng.uniform(-0.15, 0.15, (n, k - 1, 3))
    # float32 round trip: both renderers start from the values in the PLY.
    f32 = lambda a: np.asarray(a, np.float32).astype(np.float64)
    means, scales, q, sh_dc, sh_rest = map(f32, (means, scales, q, sh_dc, sh_rest))
    logit = f32(np.log(opac / (1 - opac)))
    opac = 1 / (1 + np.exp(-logit))

    to_world = np.eye(4)
    to_world[:3, :3] = R_wc @ np.diag([-1.0, -1.0, 1.0])  # Mitsuba camera: x left, y up
    to_world[:3, 3] = eye
    sh = np.concatenate([sh_dc[:, None, :], sh_rest], axis=1).reshape(n, 3 * k)
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "volprim_rf_basic", "srgb_primitives": False, "max_depth": 128},
        "sensor": {
            "type": "perspective", "fov": FOV_X_DEG, "fov_axis": "x",
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "near_clip": 0.01, "far_clip": 100.0,
            "sampler": {"type": "stratified", "sample_count": 1, "jitter": False},
            "film": {"type": "hdrfilm", "width": W, "height": H, "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
        },
        "gaussians": {
            "type": "ellipsoids",
            "centers": mi.TensorXf(means.astype(np.float32)),
            "scales": mi.TensorXf(scales.astype(np.float32)),
            # Mitsuba quaternions are xyzw.
            "quaternions": mi.TensorXf(q[:, [1, 2, 3, 0]].astype(np.float32)),
            "opacities": mi.TensorXf(opac.astype(np.float32).reshape(n, 1)),
            "sh_coeffs": mi.TensorXf(sh.astype(np.float32)),
            "extent": 4.0,
        },
    })
    img = np.array(mi.render(scene, spp=1))
    d = ensure_dir(os.path.join(OUT, name))
    write_inria_ply(os.path.join(d, "scene.ply"), means, np.log(scales), q, logit, sh_dc, sh_rest)
    fx = 0.5 * W / np.tan(np.radians(FOV_X_DEG) / 2)
    write_cameras_json(os.path.join(d, "cameras.json"),
                       [dict(name=name, width=W, height=H, fx=fx, fy=fx, R_wc=R_wc, center=eye)])
    write_exr(os.path.join(d, "rgb.exr"), img[:, :, :3])
    with open(os.path.join(d, "meta.json"), "w") as f:
        json.dump(dict(case=name, gaussians=n, sh_degree=sh_degree, width=W, height=H,
                       tool=f"mitsuba {mi.__version__} llvm_ad_rgb, ellipsoids (extent 4) + "
                            "volprim_rf_basic, 1 spp at pixel centres",
                       generator="reference_data/generate/make_mitsuba_crosscheck.py"), f, indent=1)
    print(f"{name}: {n} Gaussians, mean rgb {img[:, :, :3].mean():.4f}")


def main():
    rng = np.random.Generator(np.random.PCG64(31))
    make_case("grid_deg0_axis", rng, 0, (0, 0, 0), (0, 0, 1), (0, -1, 0))
    make_case("grid_deg1_rotated", rng, 1, (0.5, -0.3, 1.0), (-0.4, 0.2, 5.0), (0.1, -1, 0))


if __name__ == "__main__":
    main()
