"""Property-based tests of the binding's argument checks (hypothesis, pinned).

Whatever a caller passes — any dtype, shape, memory order, any float in a camera, any
integer size — the binding either computes or raises one ``ValueError`` (``OverflowError`` /
``TypeError`` where Python itself cannot convert, e.g. a negative size) whose message names
the argument; it never crashes the interpreter, never raises anything else, and never
accepts an argument the documented checks refuse. No example database is written (the
suite writes only into temporary folders).
"""

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings, strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

import unseen  # noqa: E402

W, H = 12, 9
N = 4
# Derandomized: the same examples on every run (a CI failure reproduces locally).
SETTINGS = settings(database=None, deadline=None, max_examples=150, derandomize=True)
# What each property saw: both outcomes must occur (checked by the last test), or the
# property would hold vacuously.
SEEN = {"array": set(), "camera": set()}
ARGS = ("means", "quats", "scales", "opacities", "sh")


def good_scene(degree=1):
    rng = np.random.default_rng(3)
    k = (degree + 1) ** 2
    means = np.stack([rng.uniform(-1, 1, N), rng.uniform(-1, 1, N), rng.uniform(2, 4, N)], 1)
    return dict(
        means=means.astype(np.float32),
        quats=rng.normal(size=(N, 4)).astype(np.float32),
        scales=rng.uniform(-3, -2, (N, 3)).astype(np.float32),
        opacities=rng.uniform(-1, 2, N).astype(np.float32),
        sh=(rng.normal(size=(N, k, 3)) * 0.3).astype(np.float32),
    )


def camera():
    k = np.array([[10.0, 0, W / 2], [0, 10.0, H / 2], [0, 0, 1]])
    return unseen.Camera(k, np.eye(4), W, H)


def expected_shape(name, n=N, k=4):
    return {"means": (n, 3), "quats": (n, 4), "scales": (n, 3), "opacities": (n,), "sh": (n, k, 3)}[name]


dtypes = st.sampled_from([np.float32, np.float64, np.float16, np.int32, np.int64, np.uint8, np.bool_])
shapes = hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=6)


@SETTINGS
@given(
    name=st.sampled_from(ARGS),
    dtype=dtypes,
    shape=st.one_of(shapes, st.none()),
    fortran=st.booleans(),
)
def test_any_array_is_rendered_only_when_valid_else_a_value_error_names_it(name, dtype, shape, fortran):
    scene = good_scene()
    # None: the expected shape (so that dtype and order alone decide).
    arr = np.zeros(expected_shape(name) if shape is None else shape, dtype=dtype)
    if fortran:
        arr = np.asfortranarray(arr)
    scene[name] = arr
    valid = (
        arr.dtype == np.float32
        and arr.flags.c_contiguous
        and arr.shape == expected_shape(name)
    )
    try:
        out = unseen.render(**scene, camera=camera())
    except ValueError as e:
        assert not valid, f"a valid {name} was refused: {e}"
        assert str(e).startswith(f"{name}:"), str(e)
        SEEN["array"].add("refused")
        return
    SEEN["array"].add("rendered")
    assert valid, f"{name} of dtype {arr.dtype}, shape {arr.shape}, fortran={fortran} was accepted"
    assert out["rgb"].shape == (H, W, 3)


@SETTINGS
@given(
    kind=st.sampled_from(["list", "tuple", "none", "str", "scalar", "object"]),
    name=st.sampled_from(ARGS),
)
def test_non_arrays_are_a_value_error_naming_the_argument(kind, name):
    scene = good_scene()
    scene[name] = {
        "list": scene[name].tolist(),
        "tuple": tuple(scene[name].ravel().tolist()),
        "none": None,
        "str": "means",
        "scalar": 1.0,
        "object": np.array([object()] * N, dtype=object),
    }[kind]
    with pytest.raises(ValueError, match=f"^{name}:"):
        unseen.render(**scene, camera=camera())


floats = st.floats(allow_nan=True, allow_infinity=True, width=64)


special = st.sampled_from([np.nan, np.inf, -np.inf, 0.0, -1.0, 1e300, -0.0, 5e-324])


@st.composite
def cameras(draw):
    """Mostly valid cameras (a rotation from a quaternion, a finite centre, positive focal
    lengths, a small size) with, half the time, one entry replaced by a special value."""
    q = np.array(draw(st.lists(st.floats(-1, 1), min_size=4, max_size=4)))
    q = q / np.linalg.norm(q) if np.linalg.norm(q) > 1e-3 else np.array([1.0, 0, 0, 0])
    w, x, y, z = q
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
    view = np.eye(4)
    view[:3, :3] = r
    view[:3, 3] = draw(st.lists(st.floats(-10, 10), min_size=3, max_size=3))
    f = draw(st.floats(0.1, 100))
    k = np.array([[f, 0, 4.0], [0, f, 3.0], [0, 0, 1]])
    width = draw(st.integers(min_value=-2, max_value=70_000))
    height = draw(st.integers(min_value=-2, max_value=70_000))
    if draw(st.booleans()):
        which = draw(st.sampled_from(["k", "view"]))
        m = k if which == "k" else view
        i = draw(st.integers(0, m.shape[0] - 1))
        j = draw(st.integers(0, m.shape[1] - 1))
        m[i, j] = draw(special)
    return k, view, width, height


@SETTINGS
@given(
    cam=st.one_of(
        cameras(),
        st.tuples(
            hnp.arrays(np.float64, (3, 3), elements=floats),
            hnp.arrays(np.float64, (4, 4), elements=floats),
            st.integers(min_value=-5, max_value=2**33),
            st.integers(min_value=-5, max_value=2**33),
        ),
    )
)
def test_any_camera_is_built_only_when_valid(cam):
    k, view, width, height = cam
    try:
        built = unseen.Camera(k, view, width, height)
    except (ValueError, OverflowError, TypeError):
        SEEN["camera"].add("refused")
        return
    SEEN["camera"].add("built")
    # Accepted: finite intrinsics, a proper rigid view, a size the renderer takes.
    assert np.isfinite(k).all() and np.isfinite(view).all()
    assert 0 < width <= 65536 and 0 < height <= 65536
    assert k[0, 0] > 0 and k[1, 1] > 0
    r = view[:3, :3]
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-3) and np.linalg.det(r) > 0
    assert np.array_equal(view[3], [0, 0, 0, 1])
    if width * height <= 4096:
        empty = {n: np.zeros((0,) + expected_shape(n, 0, 1)[1:], np.float32) for n in ARGS}
        out = unseen.render(**empty, camera=built)
        assert out["rgb"].shape == (height, width, 3)


@SETTINGS
@given(tolerance=floats)
def test_compare_tolerance_must_be_finite_and_non_negative(tolerance, tmp_path_factory):
    d = tmp_path_factory.mktemp("cmp")
    try:
        unseen.compare(d, d, tolerance=tolerance)
    except ValueError as e:
        if np.isfinite(tolerance) and tolerance >= 0:
            # A valid tolerance: the refusal is about the folders (not runs).
            assert "tolerance" not in str(e), str(e)
        else:
            assert "tolerance" in str(e), str(e)
    except OSError:
        assert np.isfinite(tolerance) and tolerance >= 0


def test_the_properties_saw_both_outcomes():
    """Runs last (file order): each property above met valid and invalid input."""
    assert SEEN["array"] == {"refused", "rendered"}, SEEN
    assert SEEN["camera"] == {"refused", "built"}, SEEN
