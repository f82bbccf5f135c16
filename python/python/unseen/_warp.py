"""DIBR forward warping for ports: ``compare_warp``'s cases and known mistakes (SPEC.md §18).

The warp's decisions are discrete: which target pixel (or bilinear cell) a projected point
lands in, which of two points nearly at the same depth wins the z-buffer, which
contributions fall in the depth band, and — through the hole mask — what crack closing
and hole growing do. The oracle marks every target pixel whose outcome a port's float
noise could change (``unseen.warp(...)["aside"]``: a point within ``DECISION_PX`` of a
footprint boundary, a z tie within ``DECISION_Z_REL``, a contribution at the band's limit,
and the cleaning's reach around them); every other pixel must agree: its hole status
exactly, its depth and colour within small tolerances.
"""

import numpy as np

from ._collide import _axis_angle, _rotation, viewmat
from ._stage import StageMistake

#: A port's depth may differ by this share (nearest: the point's float32 z; bilinear: a
#: weighted mean of z within the band, its weights moved by ≤ ``DECISION_PX``).
DEPTH_RTOL = 1e-4
#: A port's colour may differ by this share of the image's largest value: nearest copies a
#: value or averages a crack's window (summation order); bilinear's weights move with the
#: projection by ≤ 2e-3 px (the oracle's ``DECISION_PX``), ×4.
COLOR_ATOL_NEAREST = 1e-5
COLOR_ATOL_BILINEAR = 8e-3
#: At most this share of the target's pixels may be set aside.
MAX_SET_ASIDE = 0.25
#: ``aside`` bits of ``unseen.warp``.
ASIDE_EDGE, ASIDE_Z_TIE, ASIDE_BAND, ASIDE_CLEANING = 1, 2, 4, 8


def warp_case(seed):
    """A seeded case: an RGB float32 ``image`` (H, W, 3) and its camera-z ``depth`` (H, W)
    — a back wall 3–5 m away behind a box 1–2 m away, with noise and 3 % invalid depths
    (0, NaN, ∞) — seen from ``source`` and warped to ``target`` (``k``, ``viewmat``,
    ``width``, ``height`` each; fy within 10 % of fx, principal points off centre): the
    target turned by up to 8° and moved by 0.1–0.5 m, its size and focal length within
    20 % of the source's. ``footprint`` alternates
    nearest and bilinear; every third case cleans (``close_cracks`` 1, ``grow_holes`` 1),
    with the bilinear footprint: under magnification nearest leaves one-pixel cracks
    wherever a point lies at a pixel edge, and the cleaning's reach around them would set
    aside a third of the image."""
    rng = np.random.default_rng(np.random.PCG64(60_000 + seed))
    w, h = int(rng.integers(40, 81)), int(rng.integers(30, 61))
    f = rng.uniform(0.7, 1.3) * w
    ks = np.array([[f, 0, w / 2 + rng.uniform(-4, 4)],
                   [0, f * rng.uniform(0.9, 1.1), h / 2 + rng.uniform(-4, 4)], [0, 0, 1]],
                  np.float64)
    r_s = _rotation(rng)
    c_s = rng.uniform(-2, 2, size=3)
    tw, th = int(w * rng.uniform(0.8, 1.2)), int(h * rng.uniform(0.8, 1.2))
    ft = f * rng.uniform(0.8, 1.2)
    kt = np.array([[ft, 0, tw / 2 + rng.uniform(-3, 3)],
                   [0, ft * rng.uniform(0.9, 1.1), th / 2 + rng.uniform(-3, 3)], [0, 0, 1]],
                  np.float64)
    r_t = _axis_angle(rng.normal(size=3), np.radians(rng.uniform(0, 8))) @ r_s
    move = rng.normal(size=3)
    c_t = c_s + move / np.linalg.norm(move) * rng.uniform(0.1, 0.5)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = rng.uniform(3, 5) + 0.01 * (xx - w / 2) * rng.uniform(-1, 1)
    x0, x1 = sorted(rng.uniform(0.1, 0.9, 2) * w)
    y0, y1 = sorted(rng.uniform(0.1, 0.9, 2) * h)
    box = (xx >= x0) & (xx < max(x1, x0 + 4)) & (yy >= y0) & (yy < max(y1, y0 + 4))
    depth = np.where(box, rng.uniform(1, 2), depth) + rng.normal(0, 0.01, (h, w))
    depth = depth.astype(np.float32)
    bad = rng.random((h, w)) < 0.03
    depth[bad] = rng.choice(np.array([0.0, np.nan, np.inf], np.float32), size=int(bad.sum()))
    img = np.stack([0.5 + 0.4 * np.sin(xx / rng.uniform(3, 9) + c) * np.cos(yy / 7)
                    for c in rng.uniform(0, 6, 3)], -1)
    img = np.where(box[..., None], 1 - img, img).astype(np.float32)
    cleaning = seed % 3 == 2
    return {"image": img, "depth": depth,
            "source": {"k": ks, "viewmat": viewmat(r_s, c_s), "width": w, "height": h},
            "target": {"k": kt, "viewmat": viewmat(r_t, c_t), "width": tw, "height": th},
            "footprint": "bilinear" if cleaning else ("nearest", "bilinear")[seed % 2],
            "depth_tolerance": 0.01,
            "close_cracks": int(cleaning), "grow_holes": int(cleaning)}


WARP_MISTAKES = (
    StageMistake("corner_lift", "source pixels lifted through their corner (j, i), not their "
                 "centre (j + 0.5, i + 0.5)"),
    StageMistake("round_projection", "target pixels centred on integers (round(u)), not "
                 "covering [j, j + 1)"),
    StageMistake("last_writer", "no z-buffer: the last point written wins"),
    StageMistake("inverse_pose", "the source's world-to-camera rotation used as "
                 "camera-to-world"),
    StageMistake("depth_as_distance", "depth as the distance along the ray, not camera z"),
)


def warp_reference(case, mistake=None, dtype=np.float64):
    """A NumPy forward warp of ``case`` without cleaning (``mistake``: one of
    ``WARP_MISTAKES``' names, or None), its geometry computed in ``dtype``: ``image``,
    ``depth`` and ``holes``."""
    img, depth = case["image"].astype(np.float64), case["depth"].astype(dtype)
    s, t = ({k: (v.astype(dtype) if isinstance(v, np.ndarray) else v) for k, v in c.items()}
            for c in (case["source"], case["target"]))
    h, w, ch = img.shape
    tw, th = t["width"], t["height"]
    yy, xx = np.mgrid[0:h, 0:w].astype(dtype)
    off = dtype(0.0 if mistake == "corner_lift" else 0.5)
    z = depth.ravel()
    valid = np.isfinite(z) & (z > 0)
    ks, kt = s["k"], t["k"]
    d = np.stack([((xx + off - ks[0, 2]) / ks[0, 0]).ravel(),
                  ((yy + off - ks[1, 2]) / ks[1, 1]).ravel(), np.ones(h * w, dtype)], 1)
    if mistake == "depth_as_distance":
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
    p = d * np.where(valid, z, dtype(0))[:, None]
    r_cw = s["viewmat"][:3, :3]
    r_wc = r_cw if mistake == "inverse_pose" else r_cw.T
    c_s = -r_cw.T @ s["viewmat"][:3, 3]
    world = p @ r_wc.T + c_s
    q = world @ t["viewmat"][:3, :3].T + t["viewmat"][:3, 3]
    ok = valid & (q[:, 2] > 0)
    src = np.nonzero(ok)[0]
    q = q[ok]
    u = kt[0, 0] * q[:, 0] / q[:, 2] + kt[0, 2]
    v = kt[1, 1] * q[:, 1] / q[:, 2] + kt[1, 2]
    zt = q[:, 2].astype(np.float32).astype(np.float64)
    colours = img.reshape(-1, ch)[src]
    out = np.zeros((th * tw, ch))
    out_z = np.zeros(th * tw)
    if case["footprint"] == "nearest":
        if mistake == "round_projection":
            u, v = u + 0.5, v + 0.5
        inside = (u >= 0) & (v >= 0) & (u < tw) & (v < th)
        tgt = np.floor(v[inside]).astype(np.int64) * tw + np.floor(u[inside]).astype(np.int64)
        zz, cc, ss = zt[inside], colours[inside], src[inside]
        order = np.argsort(-ss, kind="stable") if mistake == "last_writer" else \
            np.lexsort((ss, zz))
        first = {}
        for k in order:
            first.setdefault(int(tgt[k]), k)
        for tpx, k in first.items():
            out[tpx], out_z[tpx] = cc[k], zz[k]
        holes = np.ones(th * tw, bool)
        holes[list(first)] = False
    else:
        x, y = u - 0.5, v - 0.5
        keep = (x > -1) & (y > -1) & (x < tw) & (y < th)
        x, y, zz, cc = x[keep], y[keep], zt[keep], colours[keep]
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        tgt, wgt, zs, cs = [], [], [], []
        for dy, wy in ((0, 1 - fy), (1, fy)):
            for dx, wx in ((0, 1 - fx), (1, fx)):
                px, py = x0 + dx, y0 + dy
                wv = wx * wy
                m = (wv > 0) & (px >= 0) & (py >= 0) & (px < tw) & (py < th)
                tgt.append((py[m] * tw + px[m]).astype(np.int64))
                wgt.append(wv[m])
                zs.append(zz[m])
                cs.append(cc[m])
        tgt, wgt, zs, cs = map(np.concatenate, (tgt, wgt, zs, cs))
        zmin = np.full(th * tw, np.inf)
        np.minimum.at(zmin, tgt, zs)
        band = zs <= zmin[tgt] * (1 + case["depth_tolerance"])
        wsum = np.zeros(th * tw)
        np.add.at(wsum, tgt[band], wgt[band])
        np.add.at(out_z, tgt[band], wgt[band] * zs[band])
        np.add.at(out, tgt[band], wgt[band, None] * cs[band])
        holes = wsum == 0
        nz = ~holes
        out[nz] /= wsum[nz, None]
        out_z[nz] /= wsum[nz]
    return {"image": out.reshape(th, tw, ch), "depth": out_z.reshape(th, tw),
            "holes": holes.reshape(th, tw)}


def warp_failures(got, want, aside, footprint, scale):
    """Per target pixel, whether ``got`` fails against ``want`` under ``compare_warp``'s
    rules (pixels in ``aside`` excluded): ``(holes, depth, image)`` boolean maps."""
    judged = aside == 0
    holes = judged & (np.asarray(got["holes"], bool) != want["holes"])
    both = judged & ~np.asarray(got["holes"], bool) & ~want["holes"]
    zg, zw = np.asarray(got["depth"], np.float64), np.asarray(want["depth"], np.float64)
    depth = both & ~(np.abs(zg - zw) <= DEPTH_RTOL * np.abs(zw))
    atol = (COLOR_ATOL_NEAREST if footprint == "nearest" else COLOR_ATOL_BILINEAR) * scale
    diff = np.abs(np.asarray(got["image"], np.float64) - want["image"]).max(-1)
    image = both & ~(diff <= atol)
    return holes, depth, image
