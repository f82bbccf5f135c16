"""An independent NumPy port of the 3DGS forward rasterizer, written from gsplat's formulas
(gsplat 1.5.3 `ProjectionEWA3DGSFused.cu`, `RasterizeToPixels3DGSFwd.cu`, `_torch_impl.py`),
for testing `unseen.testing` against a port that shares no code with the oracle (a helper
of the tests, not part of the package).

Two knobs:

* ``dtype``: ``np.float64`` or ``np.float32``: every intermediate is computed in it (the
  scene's float32 parameters and the camera are cast to it first).
* ``projection``: ``"textbook"`` (gsplat's and INRIA's EWA splatting: ``Σ = R S Sᵀ Rᵀ``,
  ``Σc = W Σ Wᵀ``, ``Σ2d = J Σc Jᵀ + 0.3 I``, ``det = a·c − b²``) or ``"stable"`` (the
  cancellation-free form of SPEC.md §5.1: ``Σ2d = F Fᵀ`` with ``F = J W R diag(s)``, the
  determinant as the squared norm of F's 2×2 minors ``s_i s_j (Qᵀ (J₀ × J₁))_k``, the
  dilation added as non-negative terms).

gsplat-torch's two port-side problems are fixed: the determinant is tested (``det > 0``)
before anything could clamp it (gsplat's ``_fully_fused_projection`` clamps it at 1e-10
first, so nothing is culled as degenerate), and the quaternion is normalised by its norm
without an epsilon (``F.normalize``'s 1e-12 turns a quaternion of norm 1e-20 into a
near-zero one); in float32 the norm is taken of the quaternion divided by its largest
component, so that ``|q|²`` of a quaternion of norm 1e-20 does not underflow.

The rest is gsplat's: near plane 0.01 (far 1e10), the Jacobian's clamped ``x/z, y/z``
(0.3 of the half field of view past the image), opacity ``sigmoid`` culled under 1/255,
the opacity-aware radius ``min(3.33, sqrt(2 ln(255 o)))·sqrt(diagonal)``, the footprint
cull off the image, real SH up to degree 3 (INRIA's ``sh_utils`` constants) + 0.5 clamped
at 0, 16×16 tiles, a depth sort with an index tie-break, front-to-back blending with
``α = min(max_alpha, o·exp(−σ))``, skipping ``σ < 0`` and ``α < 1/255`` and stopping
before ``T·(1 − α) ≤ 1e-4``, ``rgb = C + T·bg``. Forward only.
"""

import numpy as np

NEAR_PLANE, FAR_PLANE = 0.01, 1e10
EPS2D = 0.3
JACOBIAN_GUARD = 0.3
ALPHA_THRESHOLD = 1.0 / 255.0
MAX_EXTENT_SIGMA = 3.33
TRANSMITTANCE_STOP = 1e-4
TILE = 16
MAX_ALPHA = {"inria": 0.99, "gsplat": 0.999}

# Real SH, Condon–Shortley phase, 3DGS ordering (INRIA utils/sh_utils.py, gsplat
# _eval_sh_bases_fast).
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
         -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def sh_basis(dirs, degree):
    """(N, (degree + 1)²) basis values of unit directions (N, 3), degree ≤ 3."""
    if degree > 3:
        raise ValueError("numpy_port: SH degree ≤ 3")
    dt = dirs.dtype
    x, y, z = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    cols = [np.full_like(x, SH_C0)]
    if degree >= 1:
        c1 = dt.type(SH_C1)
        cols += [-c1 * y, c1 * z, -c1 * x]
    if degree >= 2:
        c2 = [dt.type(c) for c in SH_C2]
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        cols += [c2[0] * xy, c2[1] * yz, c2[2] * (2 * zz - xx - yy), c2[3] * xz,
                 c2[4] * (xx - yy)]
    if degree >= 3:
        c3 = [dt.type(c) for c in SH_C3]
        cols += [c3[0] * y * (3 * xx - yy), c3[1] * xy * z, c3[2] * y * (4 * zz - xx - yy),
                 c3[3] * z * (2 * zz - 3 * xx - 3 * yy), c3[4] * x * (4 * zz - xx - yy),
                 c3[5] * z * (xx - yy), c3[6] * x * (xx - 3 * yy)]
    return np.stack(cols, axis=1)


def quat_to_rotmat(q):
    """Rotation matrices (N, 3, 3) of normalised wxyz quaternions (N, 4)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    one = q.dtype.type(1)
    r = np.empty(q.shape[:1] + (3, 3), dtype=q.dtype)
    r[:, 0, 0] = one - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - w * z)
    r[:, 0, 2] = 2 * (x * z + w * y)
    r[:, 1, 0] = 2 * (x * y + w * z)
    r[:, 1, 1] = one - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - w * x)
    r[:, 2, 0] = 2 * (x * z - w * y)
    r[:, 2, 1] = 2 * (y * z + w * x)
    r[:, 2, 2] = one - 2 * (x * x + y * y)
    return r


def project(scene, camera, dtype=np.float64, projection="textbook",
            max_extent_sigma=MAX_EXTENT_SIGMA):
    """Per-Gaussian projection: dict of means2d (N, 2), conics (N, 3), colors (N, 3), depths
    (N,), opacities (N,), radii (N, 2) int32 (0 where culled), all in `dtype`."""
    if projection not in ("textbook", "stable"):
        raise ValueError(f"projection: 'textbook' or 'stable', got {projection!r}")
    dt = np.dtype(dtype)
    f = dt.type
    means = scene["means"].astype(dt)
    quats = scene["quats"].astype(dt)
    scales = np.exp(scene["scales"].astype(dt))
    logits = scene["opacities"].astype(dt)
    sh = scene["sh"].astype(dt)
    k = np.asarray(camera.k).astype(dt)
    vm = np.asarray(camera.viewmat).astype(dt)
    width, height = camera.width, camera.height
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    rcw, tcw = vm[:3, :3], vm[:3, 3]
    n = means.shape[0]
    with np.errstate(all="ignore"):
        # Camera space.
        t = means @ rcw.T + tcw
        x, y, z = t[:, 0], t[:, 1], t[:, 2]
        ok = np.isfinite(t).all(1) & np.isfinite(quats).all(1) & np.isfinite(scales).all(1)
        ok &= np.isfinite(logits)
        ok &= (z >= f(NEAR_PLANE)) & (z <= f(FAR_PLANE))
        # Rotation: q/|q|, no epsilon; the norm of q / max|q_i| (no underflow in float32).
        qmax = np.abs(quats).max(1)
        ok &= qmax > 0
        qs = quats / np.where(qmax > 0, qmax, f(1))[:, None]
        qh = qs / np.sqrt((qs * qs).sum(1))[:, None]
        rot = quat_to_rotmat(qh)
        # The clamped Jacobian (gsplat persp_proj).
        tan_fovx, tan_fovy = f(0.5) * f(width) / fx, f(0.5) * f(height) / fy
        lim_xp = (f(width) - cx) / fx + f(JACOBIAN_GUARD) * tan_fovx
        lim_xn = cx / fx + f(JACOBIAN_GUARD) * tan_fovx
        lim_yp = (f(height) - cy) / fy + f(JACOBIAN_GUARD) * tan_fovy
        lim_yn = cy / fy + f(JACOBIAN_GUARD) * tan_fovy
        tx = z * np.minimum(lim_xp, np.maximum(-lim_xn, x / z))
        ty = z * np.minimum(lim_yp, np.maximum(-lim_yn, y / z))
        jac = np.zeros((n, 2, 3), dtype=dt)
        jac[:, 0, 0] = fx / z
        jac[:, 0, 2] = -fx * tx / (z * z)
        jac[:, 1, 1] = fy / z
        jac[:, 1, 2] = -fy * ty / (z * z)
        eps = f(EPS2D)
        if projection == "textbook":
            m = rot * scales[:, None, :]  # R·S
            cov3 = m @ m.transpose(0, 2, 1)  # Σ = R S Sᵀ Rᵀ
            covc = rcw @ cov3 @ rcw.T  # Σc = W Σ Wᵀ
            cov2 = jac @ covc @ jac.transpose(0, 2, 1)  # J Σc Jᵀ
            a = cov2[:, 0, 0] + eps
            b = cov2[:, 0, 1]
            c = cov2[:, 1, 1] + eps
            det = a * c - b * b
        else:
            q = rcw @ rot  # Q = W·R
            fm = (jac @ q) * scales[:, None, :]  # F = J·Q·diag(s)
            a0 = (fm[:, 0] * fm[:, 0]).sum(1)
            c0 = (fm[:, 1] * fm[:, 1]).sum(1)
            b = (fm[:, 0] * fm[:, 1]).sum(1)
            j0, j1 = jac[:, 0], jac[:, 1]
            cross = np.stack([-j0[:, 2] * j1[:, 1], -j0[:, 0] * j1[:, 2], j0[:, 0] * j1[:, 1]], 1)
            v = np.einsum("nmk,nm->nk", q, cross)  # Qᵀ·(J₀ × J₁)
            s0, s1, s2 = scales[:, 0], scales[:, 1], scales[:, 2]
            mu = np.stack([s1 * s2 * v[:, 0], s0 * s2 * v[:, 1], s0 * s1 * v[:, 2]], 1)
            det0 = (mu * mu).sum(1)
            a, c = a0 + eps, c0 + eps
            det = (det0 + eps * (a0 + c0)) + eps * eps
        # The validity test on the determinant itself (no clamp before it).
        ok &= np.isfinite(det) & (det > 0)
        inv = f(1) / det
        conics = np.stack([c * inv, -b * inv, a * inv], 1)
        means2d = np.stack([fx * x / z + cx, fy * y / z + cy], 1)
        opac = f(1) / (f(1) + np.exp(-logits))
        ok &= opac >= f(ALPHA_THRESHOLD)
        extent = np.minimum(f(max_extent_sigma),
                            np.sqrt(f(2) * np.log(opac / f(ALPHA_THRESHOLD))))
        rx = np.ceil(extent * np.sqrt(a))
        ry = np.ceil(extent * np.sqrt(c))
        ok &= np.isfinite(rx) & np.isfinite(ry) & ((rx > 0) | (ry > 0))
        mx, my = means2d[:, 0], means2d[:, 1]
        ok &= ~((mx + rx <= 0) | (mx - rx >= width) | (my + ry <= 0) | (my - ry >= height))
        radii = np.where(ok[:, None], np.stack([rx, ry], 1), 0).astype(np.int32)
        # Colour: SH of the direction from the camera centre, + 0.5, clamped at 0.
        campos = -rcw.T @ tcw
        d = means - campos
        d = d / np.sqrt((d * d).sum(1))[:, None]
        degree = int(round(np.sqrt(sh.shape[1]))) - 1
        basis = sh_basis(d, degree)
        colors = np.maximum(np.einsum("nk,nkc->nc", basis, sh[:, :(degree + 1) ** 2]) + f(0.5),
                            f(0))
    return dict(means2d=means2d, conics=conics, colors=colors, depths=z, opacities=opac,
                radii=radii, _ok=ok)


def rasterize(proj, width, height, background, max_alpha=MAX_ALPHA["inria"]):
    """Front-to-back blending per 16×16 tile (vectorised over each tile's pixels and its
    depth-sorted list): rgb (H, W, 3), alpha (H, W), in the projection's dtype."""
    ok = proj["_ok"]
    dt = proj["means2d"].dtype
    f = dt.type
    bg = np.asarray(background, dtype=dt)
    ids = np.flatnonzero(ok)
    depths = proj["depths"][ids]
    ids = ids[np.lexsort((ids, depths))]  # depth, then index
    m2d = proj["means2d"][ids]
    r = proj["radii"][ids].astype(dt)
    tw, th = (width + TILE - 1) // TILE, (height + TILE - 1) // TILE
    x0 = np.clip(np.floor((m2d[:, 0] - r[:, 0]) / TILE), 0, tw).astype(np.int64)
    x1 = np.clip(np.ceil((m2d[:, 0] + r[:, 0]) / TILE), 0, tw).astype(np.int64)
    y0 = np.clip(np.floor((m2d[:, 1] - r[:, 1]) / TILE), 0, th).astype(np.int64)
    y1 = np.clip(np.ceil((m2d[:, 1] + r[:, 1]) / TILE), 0, th).astype(np.int64)
    conics, opac, colors = proj["conics"][ids], proj["opacities"][ids], proj["colors"][ids]
    rgb = np.empty((height, width, 3), dtype=dt)
    alpha = np.empty((height, width), dtype=dt)
    half = f(0.5)
    for ty in range(th):
        for tx in range(tw):
            sel = (x0 <= tx) & (tx < x1) & (y0 <= ty) & (ty < y1)
            ys = np.arange(ty * TILE, min((ty + 1) * TILE, height))
            xs = np.arange(tx * TILE, min((tx + 1) * TILE, width))
            py, px = (g.reshape(-1).astype(dt) + half for g in np.meshgrid(ys, xs, indexing="ij"))
            if not sel.any():
                rgb[ys[0]:ys[-1] + 1, xs[0]:xs[-1] + 1] = bg
                alpha[ys[0]:ys[-1] + 1, xs[0]:xs[-1] + 1] = 0
                continue
            mm, cc, oo, col = m2d[sel], conics[sel], opac[sel], colors[sel]
            dx = mm[None, :, 0] - px[:, None]
            dy = mm[None, :, 1] - py[:, None]
            with np.errstate(all="ignore"):
                sigma = half * (cc[None, :, 0] * dx * dx + cc[None, :, 2] * dy * dy) \
                    + cc[None, :, 1] * dx * dy
                al = np.minimum(f(max_alpha), oo[None, :] * np.exp(-sigma))
            valid = (sigma >= 0) & (al >= f(ALPHA_THRESHOLD))
            al = np.where(valid, al, f(0))
            t_incl = np.cumprod(f(1) - al, axis=1, dtype=dt)
            blended = valid & (t_incl > f(TRANSMITTANCE_STOP))
            t_before = np.concatenate([np.ones_like(t_incl[:, :1]), t_incl[:, :-1]], axis=1)
            w = np.where(blended, al * t_before, f(0))
            c = w @ col
            t_fin = np.where(blended, f(1) - al, f(1)).prod(axis=1, dtype=dt)
            shape = (len(ys), len(xs))
            rgb[ys[0]:ys[-1] + 1, xs[0]:xs[-1] + 1] = (c + t_fin[:, None] * bg).reshape(
                shape + (3,))
            alpha[ys[0]:ys[-1] + 1, xs[0]:xs[-1] + 1] = (f(1) - t_fin).reshape(shape)
    return rgb, alpha


def port(dtype=np.float64, projection="textbook", conventions="inria",
         max_extent_sigma=MAX_EXTENT_SIGMA):
    """A render callable for ``unseen.testing``: ``render(scene, camera, *, background)``
    returning rgb, alpha and the per-Gaussian intermediates (float32, as a port hands them
    over; radii int32). ``max_extent_sigma=3.0`` makes the INRIA-style 3σ footprint cap
    mistake (the oracle's is 3.33σ)."""
    max_alpha = MAX_ALPHA[conventions]

    def render(scene, camera, *, background):
        proj = project(scene, camera, dtype, projection, max_extent_sigma)
        rgb, alpha = rasterize(proj, camera.width, camera.height, background, max_alpha)
        out = {k: v.astype(np.float32) for k, v in proj.items()
               if k not in ("radii", "_ok")}
        out.update(rgb=rgb.astype(np.float32), alpha=alpha.astype(np.float32),
                   radii=proj["radii"])
        return out

    render.__name__ = f"numpy_port_{np.dtype(dtype).name}_{projection}"
    return render
