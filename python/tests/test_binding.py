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


def write_cameras(path):
    """An INRIA cameras.json with one camera at the origin looking down +z."""
    entry = {
        "id": 0,
        "img_name": "cam",
        "width": W,
        "height": H,
        "position": [0.0, 0.0, 0.0],
        "rotation": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        "fx": 38.0,
        "fy": 37.0,
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
    again = unseen.Camera(cam.k, cam.viewmat, cam.width, cam.height)
    np.testing.assert_array_equal(again.viewmat, cam.viewmat)
    a = unseen.render(**s, camera=cam)["rgb"]
    b = unseen.render(**s, camera=again)["rgb"]
    assert bits_equal(a, b)


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
