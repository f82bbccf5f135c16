"""SSIM value and gradient goldens from OpenCV + NumPy (issue #4, SPEC.md §13).

Independent of unseen: the window comes from cv2.getGaussianKernel(11, 1.5), the filtering
is cv2.sepFilter2D with BORDER_CONSTANT (zero padding, as INRIA's conv2d with padding 5),
in float64. The gradient of the mean SSIM map is written out from the product rule with
the filter's adjoint (the kernel is symmetric, so zero-padded filtering is self-adjoint)
and checked here against central differences before it is saved.

Cases (float32 H x W x 3 in [0, 1], saved as .npy):
  smooth_noise   two independent smooth random fields, 41 x 37
  texture_shift  a stripe/checker texture against a shifted, noisier copy, 48 x 40
  lounge_noisy   a crop of a Mitsuba render (reference_data/scenes/lounge) against a blurred,
                 noisier copy, 80 x 60
  nearly_equal   an image against itself + 1e-3 noise (SSIM close to 1), 33 x 29
  flat_vs_edge   a constant image against one with a hard edge (zero-variance windows), 30 x 24

Run: python make_ssim_goldens.py  (writes reference_data/opencv/ssim/<case>/)
"""
import json
import os

import cv2
import numpy as np

HERE = os.path.dirname(__file__)
OUT = os.path.join(HERE, "..", "opencv", "ssim")
C1, C2 = 0.01 ** 2, 0.03 ** 2
K = cv2.getGaussianKernel(11, 1.5, cv2.CV_64F)


def filt(a):
    return cv2.sepFilter2D(a, cv2.CV_64F, K, K, borderType=cv2.BORDER_CONSTANT)


def ssim_and_grad(x, y):
    """Mean SSIM over all pixels and channels and d(mean)/dx, per channel planes."""
    x = x.astype(np.float64)
    y = y.astype(np.float64)
    n = x.size
    total = 0.0
    grad = np.zeros_like(x)
    for c in range(x.shape[2]):
        a, b = x[:, :, c], y[:, :, c]
        mx, my = filt(a), filt(b)
        sxx = filt(a * a) - mx * mx
        syy = filt(b * b) - my * my
        sxy = filt(a * b) - mx * my
        num1, num2 = 2 * mx * my + C1, 2 * sxy + C2
        den1, den2 = mx * mx + my * my + C1, sxx + syy + C2
        s = num1 * num2 / (den1 * den2)
        total += s.sum()
        # S as a function of (mx, Exx, Exy) with sxx = Exx - mx^2, sxy = Exy - mx*my.
        d_num1_dmx = 2 * my
        d_den1_dmx = 2 * mx
        dS_dsxx = -num1 * num2 / (den1 * den2 * den2)
        dS_dsxy = 2 * num1 / (den1 * den2)
        dS_dmx_direct = d_num1_dmx * num2 / (den1 * den2) - num1 * num2 * d_den1_dmx / (den1 * den1 * den2)
        dS_dmx = dS_dmx_direct + dS_dsxx * (-2 * mx) + dS_dsxy * (-my)
        grad[:, :, c] = filt(dS_dmx) + 2 * a * filt(dS_dsxx) + b * filt(dS_dsxy)
    return total / n, grad / n


def check_fd(x, y, g, rng, count=40):
    h = 1e-6
    for _ in range(count):
        i, j, c = rng.integers(0, x.shape[0]), rng.integers(0, x.shape[1]), rng.integers(0, 3)
        xp = x.astype(np.float64).copy()
        xm = xp.copy()
        xp[i, j, c] += h
        xm[i, j, c] -= h
        fd = (ssim_and_grad(xp, y)[0] - ssim_and_grad(xm, y)[0]) / (2 * h)
        assert abs(fd - g[i, j, c]) < 1e-9 + 1e-5 * abs(fd), (fd, g[i, j, c])


def smooth(rng, h, w, cells):
    small = rng.uniform(0, 1, (cells, cells, 3)).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC).clip(0, 1)


def cases(rng):
    yield "smooth_noise", smooth(rng, 37, 41, 6), smooth(rng, 37, 41, 9)
    yy, xx = np.mgrid[0:40, 0:48]
    tex = np.stack([(np.sin(xx * 0.7) > 0) * 0.6 + 0.2,
                    ((xx // 6 + yy // 6) % 2) * 0.5 + 0.25,
                    np.full(xx.shape, 0.4) + 0.3 * np.sin(yy * 0.3)], axis=2)
    shifted = np.roll(tex, (1, 2), axis=(0, 1)) + rng.normal(0, 0.05, tex.shape)
    yield "texture_shift", tex.clip(0, 1), shifted.clip(0, 1)
    img = cv2.imread(os.path.join(HERE, "..", "scenes", "lounge", "images", "train_000.png"))
    crop = img[30:90, 40:120, ::-1].astype(np.float32) / 255.0
    noisy = cv2.GaussianBlur(crop, (5, 5), 1.0) + rng.normal(0, 0.03, crop.shape)
    yield "lounge_noisy", crop, noisy.clip(0, 1)
    base = smooth(rng, 29, 33, 5)
    yield "nearly_equal", base, (base + rng.normal(0, 1e-3, base.shape)).clip(0, 1)
    flat = np.full((24, 30, 3), 0.5)
    edge = flat.copy()
    edge[:, 15:] = 0.9
    yield "flat_vs_edge", flat, edge


def main():
    rng = np.random.Generator(np.random.PCG64(44))
    for name, x, y in cases(rng):
        x = np.ascontiguousarray(x, np.float32)
        y = np.ascontiguousarray(y, np.float32)
        s, g = ssim_and_grad(x, y)
        check_fd(x, y, g, rng)
        d = os.path.join(OUT, name)
        os.makedirs(d, exist_ok=True)
        np.save(os.path.join(d, "x.npy"), x)
        np.save(os.path.join(d, "y.npy"), y)
        np.save(os.path.join(d, "grad.npy"), g.astype(np.float32))
        with open(os.path.join(d, "meta.json"), "w") as f:
            json.dump(dict(case=name, ssim=s, height=x.shape[0], width=x.shape[1],
                           tool=f"opencv {cv2.__version__} sepFilter2D BORDER_CONSTANT float64, "
                                f"numpy {np.__version__}",
                           generator="reference_data/generate/make_ssim_goldens.py"), f, indent=1)
        print(f"{name}: ssim {s:.9f}, |grad| max {np.abs(g).max():.3e}")


if __name__ == "__main__":
    main()
