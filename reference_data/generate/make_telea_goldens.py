"""Telea inpainting goldens from OpenCV (issue #7, SPEC.md §19).

cv2.inpaint(image, mask, radius, cv2.INPAINT_TELEA) of the pinned opencv-python-headless
(requirements.txt) on image/mask pairs: procedural textures and crops of the bundled
Mitsuba renders; masks from thin scribbles to large blobs touching the border; radii 1, 3,
5, 8; 8-bit gray, 8-bit 3-channel and float32 gray. The float case is also run on values
outside [0, 1] (float inpainting does not clamp).

Per case, reference_data/opencv/telea/<case>/:
  input.png / input.npy   the image (PNG for 8-bit, .npy float32 for float)
  mask.png                8-bit, non-zero = fill
  expected.png / .npy     cv2.inpaint's output
  case.json               radius, type, OpenCV version
(cv2.imwrite stores a 3-channel array as B,G,R; inpainting treats channels independently,
so the test reads input and expected the same way and compares channel for channel.)

Run: python make_telea_goldens.py
"""
import json
import os

import cv2
import numpy as np

HERE = os.path.dirname(__file__)
OUT = os.path.join(HERE, "..", "opencv", "telea")
SCENES = os.path.join(HERE, "..", "scenes")


def smooth(rng, h, w, cells):
    g = rng.uniform(0, 1, (cells + 1, cells + 1)).astype(np.float32)
    return cv2.resize(g, (w, h), interpolation=cv2.INTER_CUBIC)


def texture(rng, h, w):
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    a = smooth(rng, h, w, 5)
    stripes = 0.5 + 0.5 * np.sin(x * 0.45 + y * 0.2)
    edge = (x + 0.6 * y > 0.55 * w).astype(np.float32)
    img = 0.45 * a + 0.3 * stripes + 0.25 * edge + rng.normal(0, 0.02, (h, w)).astype(np.float32)
    return np.clip(img, 0, 1)


def rgb_texture(rng, h, w):
    return np.stack([texture(rng, h, w) for _ in range(3)], -1)


def render(name, x0, y0, w, h):
    img = cv2.imread(os.path.join(SCENES, "lounge", "images", name + ".png"), cv2.IMREAD_COLOR)
    return img[y0:y0 + h, x0:x0 + w]


def scribble(rng, h, w, strokes, thickness):
    m = np.zeros((h, w), np.uint8)
    for _ in range(strokes):
        pts = np.cumsum(rng.integers(-9, 10, (6, 2)), 0) + [rng.integers(0, w), rng.integers(0, h)]
        cv2.polylines(m, [pts.astype(np.int32)], False, 255, thickness)
    return m


def blobs(rng, h, w, n, rmin, rmax, border=True):
    m = np.zeros((h, w), np.uint8)
    for k in range(n):
        c = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        if border and k == 0:
            c = (0, int(rng.integers(0, h)))  # one blob always touches the left border
        cv2.ellipse(m, c, (int(rng.integers(rmin, rmax)), int(rng.integers(rmin, rmax))),
                    float(rng.uniform(0, 180)), 0, 360, 255, -1)
    return m


def border_frame(h, w, width):
    m = np.zeros((h, w), np.uint8)
    m[:width, :] = 255
    m[:, -width:] = 255
    return m


def cases():
    rng = np.random.Generator(np.random.PCG64(2026))
    u8 = lambda a: np.clip(np.rint(a * 255), 0, 255).astype(np.uint8)  # noqa: E731
    yield "gray_scribble_r3", u8(texture(rng, 72, 96)), scribble(rng, 72, 96, 6, 1), 3
    yield "gray_blobs_r5", u8(texture(rng, 80, 64)), blobs(rng, 80, 64, 4, 4, 14), 5
    yield "gray_frame_r1", u8(texture(rng, 40, 52)), border_frame(40, 52, 3), 1
    yield "gray_corner_r8", u8(texture(rng, 60, 60)), blobs(rng, 60, 60, 2, 10, 22), 8
    yield "rgb_scribble_r1", u8(rgb_texture(rng, 64, 80)), scribble(rng, 64, 80, 8, 2), 1
    yield "rgb_blobs_r3", u8(rgb_texture(rng, 90, 120)), blobs(rng, 90, 120, 5, 5, 18), 3
    yield "rgb_render_blob_r5", render("train_003", 10, 10, 140, 100), blobs(rng, 100, 140, 3, 8, 25), 5
    yield "rgb_render_scribble_r3", render("heldout_010", 0, 0, 160, 120), scribble(rng, 120, 160, 10, 3), 3
    yield "rgb_render_border_r8", render("train_020", 20, 5, 120, 90), border_frame(90, 120, 6) | blobs(rng, 90, 120, 1, 12, 20), 8
    yield "rgb_tiny_holes_r3", u8(rgb_texture(rng, 25, 25)), (rng.uniform(0, 1, (25, 25)) < 0.08).astype(np.uint8) * 255, 3
    yield "float_blobs_r3", texture(rng, 70, 90) * 3.0 - 1.0, blobs(rng, 70, 90, 4, 4, 16), 3
    yield "float_scribble_r5", texture(rng, 48, 64).astype(np.float32), scribble(rng, 48, 64, 5, 2), 5


def main():
    meta = dict(tool=f"opencv-python-headless {cv2.__version__} cv2.inpaint INPAINT_TELEA",
                generator="reference_data/generate/make_telea_goldens.py", cases=[])
    for name, img, mask, radius in cases():
        d = os.path.join(OUT, name)
        os.makedirs(d, exist_ok=True)
        out = cv2.inpaint(img, mask, radius, cv2.INPAINT_TELEA)
        if img.dtype == np.float32:
            np.save(os.path.join(d, "input.npy"), img.astype(np.float32))
            np.save(os.path.join(d, "expected.npy"), out.astype(np.float32))
        else:
            cv2.imwrite(os.path.join(d, "input.png"), img)
            cv2.imwrite(os.path.join(d, "expected.png"), out)
        cv2.imwrite(os.path.join(d, "mask.png"), mask)
        info = dict(radius=radius, dtype=str(img.dtype), channels=1 if img.ndim == 2 else img.shape[2],
                    height=img.shape[0], width=img.shape[1], mask_fraction=float((mask > 0).mean()),
                    opencv=cv2.__version__)
        with open(os.path.join(d, "case.json"), "w") as f:
            json.dump(info, f, indent=1)
        meta["cases"].append(dict(name=name, **info))
        print(name, info, flush=True)
    with open(os.path.join(OUT, "meta.json"), "w") as f:
        json.dump(meta, f, indent=1)


if __name__ == "__main__":
    main()
