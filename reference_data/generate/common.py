"""Shared writers for the golden-data generators (INRIA PLY, cameras.json, EXR).

Independent of the unseen crate: these follow the file formats' public definitions.
"""
import json
import os

import numpy as np

SH_C0 = 0.28209479177387814


def write_inria_ply(path, means, log_scales, quats_wxyz, opacity_logits, sh_dc, sh_rest):
    """Write an INRIA 3DGS PLY (binary little-endian, all float).

    sh_rest is (N, K-1, 3), coefficient-major like gsplat; the file stores f_rest
    channel-major: f_rest_{c*(K-1)+j} = sh_rest[:, j, c] (INRIA save_ply transposes
    features_rest (N, K-1, 3) to (N, 3, K-1) before flattening).
    """
    n = means.shape[0]
    k1 = sh_rest.shape[1]
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * k1)]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    cols = [means, np.zeros((n, 3)), sh_dc,
            np.transpose(sh_rest, (0, 2, 1)).reshape(n, 3 * k1),
            opacity_logits.reshape(n, 1), log_scales, quats_wxyz]
    data = np.concatenate(cols, axis=1).astype("<f4")
    assert data.shape[1] == len(names)
    header = "ply\nformat binary_little_endian 1.0\n"
    header += f"element vertex {n}\n"
    header += "".join(f"property float {p}\n" for p in names)
    header += "end_header\n"
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(data.tobytes())


def camera_entry(i, c):
    """The INRIA cameras.json entry of camera dict `c` (as write_cameras_json takes) with id `i`."""
    e = {
        "id": i,
        "img_name": c["name"],
        "width": int(c["width"]),
        "height": int(c["height"]),
        "position": [float(v) for v in c["center"]],
        "rotation": [[float(v) for v in row] for row in np.asarray(c["R_wc"])],
        "fy": float(c["fy"]),
        "fx": float(c["fx"]),
    }
    if "cx" in c:
        e["cx"] = float(c["cx"])
        e["cy"] = float(c["cy"])
    return e


def write_cameras_json(path, cams):
    """cams: list of dicts with name, width, height, fx, fy, R_wc (3x3 world_from_camera,
    OpenCV frame), center (3,), optional cx, cy."""
    out = [camera_entry(i, c) for i, c in enumerate(cams)]
    with open(path, "w") as f:
        json.dump(out, f, indent=1)


def look_at(eye, target, up):
    """world_from_camera rotation (OpenCV frame: +x right, +y down, +z forward)."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(-up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def write_exr(path, img):
    """Float32 EXR, channels Y (2-D or one-channel `img`) or R, G, B, ZIP compression.

    Mitsuba's Bitmap, which this used before, writes PIZ: on the Dr.Jit raster goldens'
    float32 renders PIZ stores the raw samples (no gain) and ZIP, lossless, was
    0.6 % smaller over all 30 files (1 903 900 -> 1 891 571 bytes; ZIPS 3.6 % larger) and
    28 % smaller on the Mitsuba cross-check renders (306 688 -> 219 578 bytes).
    recompress_exr_zip.py re-encodes older PIZ files."""
    import OpenEXR

    img = np.ascontiguousarray(img, dtype=np.float32)
    if img.ndim == 2:
        img = img[:, :, None]
    names = {1: ["Y"], 3: ["R", "G", "B"]}.get(img.shape[2])
    if names is None:
        raise ValueError(f"write_exr: {img.shape[2]} channels, want 1 or 3")
    channels = {n: np.ascontiguousarray(img[:, :, k]) for k, n in enumerate(names)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, channels).write(str(path))


def write_depth_exr(path, z):
    """Camera-z depth as a float32 EXR, channel Y, ZIP compression (zlib over 16-line
    blocks with OpenEXR's byte reordering and delta predictor: lossless; on the rooms' depths
    17 % smaller than the PIZ Mitsuba's Bitmap writes, which gains nothing on float32).
    Run make_depth_manifest.py after writing depths."""
    import OpenEXR

    z = np.ascontiguousarray(z, dtype=np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"Y": z}).write(str(path))


def ensure_dir(path):
    os.makedirs(path, exist_ok=True)
    return path
