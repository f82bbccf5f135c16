"""Resize goldens from OpenCV (issue #7, SPEC.md §19.4): cv2.resize of float32 images with
INTER_LINEAR and INTER_CUBIC, up and down, 1 and 3 channels — what the ONNX adapter uses to
bring images to a model's size and back.

Written: reference_data/opencv/resize/<case>/{input.npy, expected.npy, case.json}.

Run: python make_resize_goldens.py
"""
import json
import os

import cv2
import numpy as np

OUT = os.path.join(os.path.dirname(__file__), "..", "opencv", "resize")


def main():
    rng = np.random.Generator(np.random.PCG64(31))
    cases = [
        ("linear_up_rgb", (15, 20, 3), (37, 29), cv2.INTER_LINEAR, "bilinear"),
        ("linear_down_gray", (48, 64, 1), (23, 17), cv2.INTER_LINEAR, "bilinear"),
        ("cubic_up_rgb", (12, 16, 3), (40, 30), cv2.INTER_CUBIC, "bicubic"),
        ("cubic_down_rgb", (60, 80, 3), (28, 21), cv2.INTER_CUBIC, "bicubic"),
        ("cubic_da_gray", (30, 40, 1), (70, 56), cv2.INTER_CUBIC, "bicubic"),
    ]
    for name, shape, (w, h), interp, filt in cases:
        img = rng.uniform(0, 1, shape).astype(np.float32)
        src = img[:, :, 0] if shape[2] == 1 else img
        out = cv2.resize(src, (w, h), interpolation=interp).astype(np.float32)
        if out.ndim == 2:
            out = out[:, :, None]
        d = os.path.join(OUT, name)
        os.makedirs(d, exist_ok=True)
        np.save(os.path.join(d, "input.npy"), img)
        np.save(os.path.join(d, "expected.npy"), out)
        with open(os.path.join(d, "case.json"), "w") as f:
            json.dump(dict(filter=filt, width=w, height=h, opencv=cv2.__version__), f, indent=1)
        print(name, shape, "->", out.shape)


if __name__ == "__main__":
    main()
