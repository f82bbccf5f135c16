"""The binding against the command line's `.npy` dumps, bit for bit, and its errors.

Needs the `unseen` binary: `UNSEEN_BIN`, else `target/release/unseen` or
`target/debug/unseen` of this repository (`cargo build`, or `cargo test` builds it).
"""

import json
import os
import pathlib
import shutil
import subprocess
import zlib
import struct

import numpy as np
import pytest

import unseen

REPO = pathlib.Path(__file__).resolve().parents[2]
W, H = 40, 30


def unseen_bin():
    env = os.environ.get("UNSEEN_BIN")
    if env:
        return env
    for profile in ("release", "debug"):
        p = REPO / "target" / profile / "unseen"
        if p.is_file():
            return str(p)
    raise RuntimeError(
        "no unseen binary: set UNSEEN_BIN or run `cargo build --release` in the repository"
    )


def cli(*args):
    r = subprocess.run([unseen_bin(), *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r


def random_scene(n, degree, seed):
    """Gaussians in front of the camera below, gsplat conventions, float32."""
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    means = np.stack(
        [rng.uniform(-1.2, 1.2, n), rng.uniform(-0.9, 0.9, n), rng.uniform(2.0, 6.0, n)], 1
    )
    return dict(
        means=np.ascontiguousarray(means, dtype=np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
        scales=rng.uniform(-3.5, -1.5, (n, 3)).astype(np.float32),
        opacities=rng.uniform(-2.0, 3.0, n).astype(np.float32),
        sh=(rng.normal(size=(n, k, 3)) * np.where(np.arange(k) == 0, 1.0, 0.3)[None, :, None])
        .astype(np.float32),
    )


def rotation(ax, ay, az):
    """world_from_camera: rotations about x, y, z (radians), composed z·y·x."""
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


R_WC = rotation(0.12, -0.2, 0.07)
CENTER = np.array([0.3, -0.2, -0.5])
FX, FY = 38.0, 37.0


def write_cameras(path):
    """An INRIA cameras.json with one turned and moved camera (rotation = world_from_camera,
    rows; position = centre)."""
    entry = {
        "id": 0,
        "img_name": "cam",
        "width": W,
        "height": H,
        "position": CENTER.tolist(),
        "rotation": R_WC.tolist(),
        "fx": FX,
        "fy": FY,
    }
    path.write_text(json.dumps([entry]))


def write_png(path, rgb8):
    """A minimal RGB PNG (no dependency beyond zlib)."""
    h, w, _ = rgb8.shape
    raw = b"".join(b"\x00" + rgb8[i].tobytes() for i in range(h))

    def chunk(tag, data):
        return (
            struct.pack(">I", len(data))
            + tag
            + data
            + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
        )

    png = (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )
    path.write_bytes(png)


def bits_equal(a, b):
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    return a.tobytes() == b.tobytes()


@pytest.fixture(scope="module")
def dumps(tmp_path_factory):
    """A seeded scene, its cameras and the CLI's forward and backward oracle dumps."""
    d = tmp_path_factory.mktemp("oracle")
    s = random_scene(300, 3, seed=7)
    unseen.save_ply(d / "scene.ply", **s)
    write_cameras(d / "cameras.json")
    rng = np.random.default_rng(3)
    write_png(d / "target.png", rng.integers(0, 256, (H, W, 3), dtype=np.uint8))
    common = ["--scene", d / "scene.ply", "--cameras", d / "cameras.json"]
    cli("oracle", "forward", *common, "--out", d / "fwd")
    cli("oracle", "backward", *common, "--out", d / "bwd", "--target", d / "target.png",
        "--loss", "l2")
    # A depth target: another scene's accumulated depth, rendered by the CLI.
    unseen.save_ply(d / "other.ply", **random_scene(300, 3, seed=8))
    cli("render", d / "other.ply", "--cameras", d / "cameras.json", "--outputs", "depth",
        "--out", d / "other")
    cli("oracle", "backward", *common, "--out", d / "bwd_depth", "--target", d / "target.png",
        "--loss", "l1", "--depth-target", d / "other" / "cam.depth.exr")
    return d, s


def load(d, name):
    return np.load(d / f"{name}.npy")


FORWARD = ["rgb", "alpha", "depth", "expected_depth", "final_t", "n_contrib", "means2d",
           "conics", "depths", "opacities", "colors", "radii", "tile_offsets", "tile_ids"]


@pytest.mark.parametrize("threads", [1, 2])
def test_render_matches_the_cli_bit_for_bit(dumps, threads):
    d, s = dumps
    cam = unseen.load_cameras(d / "cameras.json")[0]
    out = unseen.render(**s, camera=cam, threads=threads)
    for name in FORWARD:
        assert bits_equal(out[name], load(d / "fwd", name)), name


def test_render_computes_only_the_images_asked_for(dumps):
    d, s = dumps
    cam = unseen.load_cameras(d / "cameras.json")[0]
    out = unseen.render(**s, camera=cam, outputs=["rgb"])
    assert "alpha" not in out and "final_t" not in out
    assert bits_equal(out["rgb"], load(d / "fwd", "rgb"))


@pytest.mark.parametrize("threads", [1, 2])
def test_backward_matches_the_cli_bit_for_bit(dumps, threads):
    d, s = dumps
    cam = unseen.load_cameras(d / "cameras.json")[0]
    b = d / "bwd"
    g = unseen.backward(**s, camera=cam, grad_rgb=load(b, "v_rgb"), threads=threads)
    assert bits_equal(g["means"], load(b, "grad_means"))
    assert bits_equal(g["quats"], load(b, "grad_quats"))
    assert bits_equal(g["scales"], load(b, "grad_log_scales"))
    assert bits_equal(g["opacities"], load(b, "grad_opacity_logits"))
    assert bits_equal(np.ascontiguousarray(g["sh"][:, 0, :]), load(b, "grad_sh_dc"))
    assert bits_equal(np.ascontiguousarray(g["sh"][:, 1:, :]), load(b, "grad_sh_rest"))
    assert bits_equal(g["background"], load(b, "grad_background"))
    assert bits_equal(g["means2d"], load(b, "grad_means2d"))


def test_backward_with_a_depth_gradient_matches_the_cli(dumps):
    d, s = dumps
    cam = unseen.load_cameras(d / "cameras.json")[0]
    b = d / "bwd_depth"
    v_depth = load(b, "v_depth")
    assert np.count_nonzero(v_depth) > 100
    g = unseen.backward(**s, camera=cam, grad_rgb=load(b, "v_rgb"), grad_depth=v_depth)
    assert bits_equal(g["means"], load(b, "grad_means"))
    assert bits_equal(g["scales"], load(b, "grad_log_scales"))
    assert bits_equal(g["quats"], load(b, "grad_quats"))
    assert bits_equal(g["opacities"], load(b, "grad_opacity_logits"))
    # Without the depth term the geometry gradients change: the term is really there.
    g0 = unseen.backward(**s, camera=cam, grad_rgb=load(b, "v_rgb"))
    assert not bits_equal(g0["means"], g["means"])


def test_kernels_give_the_same_bits(dumps):
    d, s = dumps
    cam = unseen.load_cameras(d / "cameras.json")[0]
    ref = unseen.render(**s, camera=cam, kernel="scalar")
    for k in ("auto", "avx2"):
        out = unseen.render(**s, camera=cam, kernel=k)
        assert bits_equal(out["rgb"], ref["rgb"]), k


def test_ply_round_trip(tmp_path):
    s = random_scene(50, 2, seed=11)
    unseen.save_ply(tmp_path / "s.ply", **s)
    back = unseen.load_ply(tmp_path / "s.ply")
    assert back["sh_degree"] == 2
    for k, v in s.items():
        assert bits_equal(back[k], v), k


def test_camera_from_viewmat_matches_cameras_json(dumps):
    d, s = dumps
    cam = unseen.load_cameras(d / "cameras.json")[0]
    # gsplat's viewmat from the camera's pose, independently of the binding.
    r_cw = R_WC.T
    viewmat = np.eye(4)
    viewmat[:3, :3], viewmat[:3, 3] = r_cw, -r_cw @ CENTER
    k = np.array([[FX, 0, W / 2], [0, FY, H / 2], [0, 0, 1]])
    np.testing.assert_allclose(cam.viewmat, viewmat, atol=1e-15)
    np.testing.assert_array_equal(cam.k, k)
    again = unseen.Camera(k, viewmat, W, H)
    np.testing.assert_allclose(again.viewmat, viewmat, atol=1e-15)
    out = unseen.render(**s, camera=again)
    np.testing.assert_allclose(out["rgb"], unseen.render(**s, camera=cam)["rgb"], atol=1e-6)
    # The projected centres are the pinhole projection of the means (f32 against f64).
    x = (r_cw @ (s["means"].astype(np.float64) - CENTER).T).T
    uv = np.stack([FX * x[:, 0] / x[:, 2] + W / 2, FY * x[:, 1] / x[:, 2] + H / 2], 1)
    seen = (out["radii"] > 0).any(1)
    assert seen.sum() > 100
    np.testing.assert_allclose(out["means2d"][seen], uv[seen], atol=2e-4)
    np.testing.assert_allclose(out["depths"][seen], x[seen, 2], rtol=1e-6)


def test_compare_finds_the_first_divergent_step(dumps, tmp_path):
    d, _ = dumps
    # Two runs of one step each: the forward dump, and in B with one pixel moved.
    for run in ("a", "b"):
        shutil.copytree(d / "fwd", tmp_path / run / "render")
    rgb = load(tmp_path / "b" / "render", "rgb")
    rgb[3, 4, 1] += np.float32(1e-3)
    np.save(tmp_path / "b" / "render" / "rgb.npy", rgb)
    same = unseen.compare(tmp_path / "a", tmp_path / "a")
    assert same["first_divergent"] is None
    other = unseen.compare(tmp_path / "a", tmp_path / "b")
    assert other["first_divergent"] == "render"
    (diff,) = [f for f in other["steps"][0]["files"] if f["path"] == "rgb.npy"]
    assert not diff["identical"] and abs(diff["max_abs"] - 1e-3) < 1e-6
    assert unseen.compare(tmp_path / "a", tmp_path / "b", tolerance=1e-2)["first_divergent"] is None
    with pytest.raises(ValueError, match="not a run directory"):
        unseen.compare(tmp_path / "a", tmp_path / "missing")


def test_zero_gaussians_render_the_background(cam):
    empty = random_scene(0, 0, seed=1)
    out = unseen.render(**empty, camera=cam, background=[0.25, 0.5, 1.0])
    assert out["rgb"].shape == (H, W, 3)
    np.testing.assert_array_equal(out["rgb"][5, 7], np.float32([0.25, 0.5, 1.0]))
    assert out["means2d"].shape == (0, 2)
    g = unseen.backward(**empty, camera=cam, grad_rgb=np.ones((H, W, 3), np.float32))
    assert g["sh"].shape == (0, 1, 3) and g["background"].tolist() == [H * W] * 3


def test_versions():
    v = unseen.versions()
    assert v["conventions"] >= 1 and v["numerics_revision"] >= 1 and v["crate"]


# Bad input: one clear ValueError (OSError for missing files) naming the argument.


@pytest.fixture
def good():
    return random_scene(10, 1, seed=1)


@pytest.fixture
def cam():
    k = np.array([[30.0, 0, 20], [0, 30.0, 15], [0, 0, 1]])
    return unseen.Camera(k, np.eye(4), W, H)


def test_wrong_dtype_names_the_argument_and_shape(good, cam):
    bad = dict(good, means=good["means"].astype(np.float64))
    with pytest.raises(ValueError, match=r"means: expected a C-contiguous float32 array of shape \(N, 3\), got dtype float64"):
        unseen.render(**bad, camera=cam)


def test_a_list_is_refused(good, cam):
    bad = dict(good, opacities=list(good["opacities"]))
    with pytest.raises(ValueError, match=r"opacities: .*\(N,\), got list"):
        unseen.render(**bad, camera=cam)


def test_non_contiguous_is_refused(good, cam):
    bad = dict(good, scales=np.asfortranarray(good["scales"]))
    assert not bad["scales"].flags.c_contiguous
    with pytest.raises(ValueError, match="scales: .*non-contiguous"):
        unseen.render(**bad, camera=cam)


def test_mismatched_counts_are_refused(good, cam):
    bad = dict(good, quats=good["quats"][:5].copy())
    with pytest.raises(ValueError, match=r"quats: .*\(N, 4\) \(N = 10\), got shape \[5, 4\]"):
        unseen.render(**bad, camera=cam)


def test_wrong_sh_count_is_refused(good, cam):
    bad = dict(good, sh=np.zeros((10, 5, 3), np.float32))
    with pytest.raises(ValueError, match="sh: expected K = .* got K = 5"):
        unseen.render(**bad, camera=cam)


def test_wrong_gradient_image_size_is_refused(good, cam):
    with pytest.raises(ValueError, match=r"grad_rgb: .*\(30, 40, 3\), got shape \[40, 30, 3\]"):
        unseen.backward(**good, camera=cam, grad_rgb=np.zeros((W, H, 3), np.float32))


def test_bad_cameras_are_refused():
    k = np.array([[0.0, 0, 20], [0, 30.0, 15], [0, 0, 1]])
    with pytest.raises(ValueError, match="focal length fx = 0"):
        unseen.Camera(k, np.eye(4), W, H)
    k = np.array([[30.0, 0, 20], [0, 30.0, 15], [0, 0, 1]])
    with pytest.raises(ValueError, match="not a proper rotation"):
        unseen.Camera(k, np.diag([1.0, 1.0, -1.0, 1.0]), W, H)
    with pytest.raises(ValueError, match="last row"):
        unseen.Camera(k, np.ones((4, 4)), W, H)


def test_oversized_cameras_are_refused():
    k = np.array([[30.0, 0, 20], [0, 30.0, 15], [0, 0, 1]])
    with pytest.raises(ValueError, match="larger than 65536 pixels a side"):
        unseen.Camera(k, np.eye(4), 2**32 - 1, 128)
    with pytest.raises(ValueError, match="image size 60000x60000 is larger"):
        unseen.Camera(k, np.eye(4), 60000, 60000)


def test_bad_tolerance_and_single_step_folder_are_refused(dumps):
    d, _ = dumps
    with pytest.raises(ValueError, match="tolerance NaN must be finite"):
        unseen.compare(d, d, tolerance=float("nan"))
    with pytest.raises(ValueError, match="pass the folder that holds it"):
        unseen.compare(d / "fwd", d / "fwd")


def test_unknown_kernel_and_output_are_refused(good, cam):
    with pytest.raises(ValueError, match="kernel: expected"):
        unseen.render(**good, camera=cam, kernel="gpu")
    with pytest.raises(ValueError, match="outputs: expected"):
        unseen.render(**good, camera=cam, outputs=["normals"])


def test_missing_and_malformed_files_name_the_file(tmp_path):
    with pytest.raises(OSError, match="nothing.ply"):
        unseen.load_ply(tmp_path / "nothing.ply")
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat ascii 1.0\n")
    with pytest.raises(ValueError, match="bad.ply"):
        unseen.load_ply(tmp_path / "bad.ply")
    (tmp_path / "cams.json").write_text("[{")
    with pytest.raises(ValueError, match="cams.json"):
        unseen.load_cameras(tmp_path / "cams.json")


def test_save_ply_leaves_nothing_on_bad_input(good, tmp_path):
    bad = dict(good, means=np.full((10, 3), np.nan, np.float32))
    with pytest.raises(ValueError):
        unseen.save_ply(tmp_path / "x.ply", **bad)
    assert list(tmp_path.iterdir()) == []


TINY = {
    "slots": {k: "truth" for k in ("inpaint", "depth", "video", "video_depth", "fixer")},
    "qa_iterations": 30,
    "video_frames": 3,
    "stage1": {"iterations": 60, "densify": None},
    "stage2": {"iterations": 60, "densify": None},
    "interpolate": {"iterations": 40, "densify": None},
    "fixer_every": 20,
}


def test_extrapolate_equals_the_cli_run(tmp_path):
    """The pipeline from Python and from the command line, on a 300-iteration lounge run
    at 40×30 with the quick preset shrunk to seconds: the same bits in every step."""
    lounge = REPO / "reference_data" / "scenes" / "lounge"
    cli("train", lounge, "--out", tmp_path / "run", "--iterations", 300, "--resolution", 4)
    (tmp_path / "tiny.json").write_text(json.dumps(TINY))
    views = dict(evaluation=lounge / "evaluation.json", dataset=lounge)
    cli("extrapolate", tmp_path / "run", "--views", lounge / "candidates.json",
        "--eval", views["evaluation"], "--dataset", lounge, "--config", tmp_path / "tiny.json",
        "--out", tmp_path / "cli")
    scene, steps = unseen.extrapolate(
        tmp_path / "run", lounge / "candidates.json", tmp_path / "py", config=TINY,
        threads=2, **views,
    )
    assert pathlib.Path(scene) == tmp_path / "py" / "interpolate" / "recon" / "scene.ply"
    assert "stage1/recon" in steps and "interpolate/recon" in steps
    c = unseen.compare(tmp_path / "cli", tmp_path / "py")
    assert c["first_divergent"] is None
    assert all(s["identical"] for s in c["steps"])
    with pytest.raises(ValueError, match="invalid pipeline config"):
        unseen.extrapolate(tmp_path / "run", lounge / "candidates.json", tmp_path / "bad",
                           config={"qa_iterations": "many"}, **views)
    assert not (tmp_path / "bad").exists()


def test_cutoffs_are_a_forward_knob(dumps):
    """The blend's cut-offs (SPEC.md §5.4): gsplat's given explicitly give the default's
    bits, others change the image, bad values are refused."""
    d, s = dumps
    cam = unseen.load_cameras(d / "cameras.json")[0]
    default = unseen.render(**s, camera=cam, outputs=["rgb"])["rgb"]
    explicit = unseen.render(**s, camera=cam, outputs=["rgb"], inv_alpha_threshold=255.0,
                             transmittance_stop=1e-4)["rgb"]
    assert default.tobytes() == explicit.tobytes()
    for inv, stop in [(1000.0, 1e-4), (float("inf"), 0.0)]:
        rgb = unseen.render(**s, camera=cam, outputs=["rgb"], inv_alpha_threshold=inv,
                            transmittance_stop=stop)["rgb"]
        assert np.isfinite(rgb).all() and rgb.tobytes() != default.tobytes()
    for inv, stop in [(0.5, 1e-4), (float("nan"), 1e-4), (255.0, 1.0)]:
        with pytest.raises(ValueError):
            unseen.render(**s, camera=cam, inv_alpha_threshold=inv, transmittance_stop=stop)


def test_float32_cameras_equal_float64_ones(good):
    """gsplat passes K and viewmat as float32: widened exactly, the same camera."""
    k = np.array([[30.25, 0, 20.5], [0, 29.75, 15.0], [0, 0, 1]])
    a, b = 0.1, -0.2
    vm = np.eye(4)
    vm[:3, :3] = [[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]]
    vm[:3, :3] = vm[:3, :3] @ [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    vm[:3, 3] = [0.1, -0.05, 0.2]
    k32, vm32 = k.astype(np.float32), vm.astype(np.float32)
    c32 = unseen.Camera(k32, vm32, W, H)
    c64 = unseen.Camera(k32.astype(np.float64), vm32.astype(np.float64), W, H)
    assert c32.k.dtype == np.float64 and np.array_equal(c32.viewmat, c64.viewmat)
    r32 = unseen.render(**good, camera=c32)["rgb"]
    assert r32.tobytes() == unseen.render(**good, camera=c64)["rgb"].tobytes()
    with pytest.raises(ValueError, match=r"k: expected a C-contiguous float64 \(or float32\) array"):
        unseen.Camera(k.astype(np.int64), vm, W, H)


def test_conventions_reach_forward_and_backward(cam):
    """An opaque Gaussian: α at the profile's clamp (0.99 inria, 0.999 gsplat)."""
    s = dict(means=np.float32([[0, 0, 3]]), quats=np.float32([[1, 0, 0, 0]]),
             scales=np.float32([[8, 8, 8]]), opacities=np.float32([100]),
             sh=np.zeros((1, 1, 3), np.float32))
    for conv, clamp in (("inria", 0.99), ("gsplat", 0.999)):
        out = unseen.render(**s, camera=cam, conventions=conv)
        assert (out["alpha"] == np.float32(1) - (np.float32(1) - np.float32(clamp))).all()
        g = unseen.backward(**s, camera=cam, conventions=conv,
                            grad_rgb=np.ones((H, W, 3), np.float32))
        assert g["opacities"][0] == 0.0  # α at the clamp everywhere it is drawn
    with pytest.raises(ValueError, match="conventions: unknown conventions 'cuda'"):
        unseen.render(**s, camera=cam, conventions="cuda")


def test_diagnostics_flag_decisions_and_leave_the_render_alone(good, cam):
    plain = unseen.render(**good, camera=cam)
    out = unseen.render(**good, camera=cam, diagnostics=True, margins={"depth": 1e-6})
    assert out["rgb"].tobytes() == plain["rgb"].tobytes()
    d = out["diagnostics"]
    assert d["pixel_flags"].shape == (H, W) and d["pixel_flags"].dtype == np.uint8
    assert d["rgb_error"].shape == (H, W) and (d["rgb_error"] >= 0).all()
    assert d["gaussian_flags"].shape == (10,)
    assert d["margins"]["depth"] == np.float32(1e-6) and d["margins"]["sigma"] > 0
    with pytest.raises(ValueError, match="margins: expected keys"):
        unseen.render(**good, camera=cam, diagnostics=True, margins={"alpah": 1e-6})
    with pytest.raises(ValueError, match="decision margin sigma"):
        unseen.render(**good, camera=cam, diagnostics=True, margins={"sigma": 0.5})
