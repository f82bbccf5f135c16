//! `unseen._unseen`: the Python binding of the core crate (wrapped by the `unseen` package).
//!
//! Arrays in, arrays out: every function checks its NumPy arguments (dtype, C order, shape;
//! a `ValueError` naming the argument and the expected shape), copies them into the core's
//! types, releases the GIL and calls the core's public API in a pool of `threads` threads
//! (results do not depend on the count, SPEC.md §6). No numerics live here.
//!
//! Parameters follow gsplat's conventions, which are the core's raw parameters: `quats`
//! wxyz (not necessarily normalised), `scales` log scales, `opacities` logits, `sh`
//! `(N, K, 3)` with `K = (degree + 1)²` (coefficient 0 the DC term), cameras from a 3×3
//! `K` and a 4×4 world-to-camera `viewmat` (OpenCV axes: x right, y down, z forward).

use numpy::{
    PyArray1, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods, dtype,
};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use unseen::camera::Camera;
use unseen::gaussian::Gaussians;
use unseen::math::sh::num_coeffs;
use unseen::raster::backward::{GradGroups, ImageGrads, backward as core_backward};
use unseen::raster::decisions::{Decisions, Margins, decisions};
use unseen::raster::{Conventions, Cutoffs, Kernel, Outputs, RenderOptions, RenderPlan};
use unseen::{Error, ErrorKind};

/// A core error as a Python exception: `OSError` for the operating system's failures,
/// `ValueError` for everything else (malformed files, invalid arguments).
fn py_err(e: Error) -> PyErr {
    match e.kind {
        ErrorKind::Io => PyOSError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// A shape as text, `None` dimensions as their letter: `(N, 3)`.
fn shape_text(dims: &[(Option<usize>, &str)]) -> String {
    let parts: Vec<String> = dims
        .iter()
        .map(|(d, l)| d.map_or_else(|| l.to_string(), |v| v.to_string()))
        .collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// The values of `obj`, which must be a C-contiguous NumPy array of `T` with the shape
/// `dims` (a `None` dimension takes any size, and every dimension of the same letter must
/// agree with `bound`, the sizes fixed so far by letter).
fn array<T: numpy::Element + Copy>(
    name: &str,
    obj: &Bound<'_, PyAny>,
    dims: &[(Option<usize>, &str)],
    bound: &mut Vec<(String, usize)>,
) -> PyResult<(Vec<usize>, Vec<T>)> {
    let py = obj.py();
    let want = format!(
        "{name}: expected a C-contiguous {} array of shape {}",
        dtype::<T>(py),
        shape_text(dims)
    );
    let Ok(arr) = obj.cast::<PyUntypedArray>() else {
        return Err(PyValueError::new_err(format!(
            "{want}, got {}",
            obj.get_type().name()?
        )));
    };
    if !arr.dtype().is_equiv_to(&dtype::<T>(py)) {
        return Err(PyValueError::new_err(format!(
            "{want}, got dtype {}",
            arr.dtype()
        )));
    }
    let shape = arr.shape().to_vec();
    let mut ok = shape.len() == dims.len();
    if ok {
        for (&s, &(d, letter)) in shape.iter().zip(dims) {
            match d {
                Some(v) => ok &= s == v,
                None => match bound.iter().find(|(l, _)| l == letter) {
                    Some(&(_, v)) => ok &= s == v,
                    None => bound.push((letter.to_string(), s)),
                },
            }
        }
    }
    if !ok {
        let fixed: Vec<String> = bound.iter().map(|(l, v)| format!("{l} = {v}")).collect();
        return Err(PyValueError::new_err(format!(
            "{want}{}, got shape {shape:?}",
            if fixed.is_empty() {
                String::new()
            } else {
                format!(" ({})", fixed.join(", "))
            }
        )));
    }
    if !arr.is_c_contiguous() {
        return Err(PyValueError::new_err(format!(
            "{want}, got a non-contiguous array (use numpy.ascontiguousarray)"
        )));
    }
    let typed = arr
        .cast::<PyArrayDyn<T>>()
        .map_err(|_| PyValueError::new_err(want.clone()))?;
    let ro = typed.try_readonly().map_err(|_| {
        PyValueError::new_err(format!(
            "{name}: the array is borrowed mutably elsewhere and cannot be read"
        ))
    })?;
    let values = ro
        .as_slice()
        .map_err(|_| {
            PyValueError::new_err(format!(
                "{want}, got an unaligned array (use numpy.ascontiguousarray or a copy)"
            ))
        })?
        .to_vec();
    Ok((shape, values))
}

/// `v` as a NumPy array of `shape`.
fn to_numpy<'py, T: numpy::Element>(
    py: Python<'py>,
    v: Vec<T>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, v).reshape(shape)?.into_any())
}

fn triples<const K: usize>(v: &[f32]) -> Vec<[f32; K]> {
    v.chunks_exact(K)
        .map(|c| std::array::from_fn(|i| c[i]))
        .collect()
}

/// The scene from gsplat-convention arrays.
fn scene(
    means: &Bound<'_, PyAny>,
    quats: &Bound<'_, PyAny>,
    scales: &Bound<'_, PyAny>,
    opacities: &Bound<'_, PyAny>,
    sh: &Bound<'_, PyAny>,
) -> PyResult<Gaussians> {
    let mut b = Vec::new();
    let (_, m) = array::<f32>("means", means, &[(None, "N"), (Some(3), "")], &mut b)?;
    let (_, q) = array::<f32>("quats", quats, &[(None, "N"), (Some(4), "")], &mut b)?;
    let (_, s) = array::<f32>("scales", scales, &[(None, "N"), (Some(3), "")], &mut b)?;
    let (_, o) = array::<f32>("opacities", opacities, &[(None, "N")], &mut b)?;
    let (shape, c) = array::<f32>("sh", sh, &[(None, "N"), (None, "K"), (Some(3), "")], &mut b)?;
    let k = shape[1];
    let Some(degree) = (0..=unseen::math::sh::MAX_SH_DEGREE).find(|&d| num_coeffs(d) == k) else {
        return Err(PyValueError::new_err(format!(
            "sh: expected K = (degree + 1)² coefficients with degree 0..=5 (1, 4, 9, 16, 25 or 36), got K = {k}"
        )));
    };
    let n = shape[0];
    let mut dc = Vec::with_capacity(n);
    let mut rest = Vec::with_capacity(n * (k - 1) * 3);
    for g in c.chunks_exact(k * 3) {
        dc.push([g[0], g[1], g[2]]);
        rest.extend_from_slice(&g[3..]);
    }
    let g = Gaussians {
        means: triples(&m),
        log_scales: triples(&s),
        quats: triples(&q),
        opacity_logits: o,
        sh_dc: dc,
        sh_rest: rest,
        sh_degree: degree,
    };
    g.validate().map_err(py_err)?;
    Ok(g)
}

fn kernel(name: &str) -> PyResult<Kernel> {
    match name {
        "auto" => Ok(Kernel::Auto),
        "avx2" => Ok(Kernel::Avx2),
        "scalar" => Ok(Kernel::Scalar),
        _ => Err(PyValueError::new_err(format!(
            "kernel: expected 'auto', 'avx2' or 'scalar', got {name:?}"
        ))),
    }
}

/// Render options; the core checks them (a non-finite background, an SH degree above 5).
fn options(
    background: [f32; 3],
    sh_degree: Option<u32>,
    kernel_name: &str,
    conventions: &str,
) -> PyResult<RenderOptions> {
    Ok(RenderOptions {
        background,
        sh_degree,
        kernel: kernel(kernel_name)?,
        conventions: Conventions::parse(conventions)
            .map_err(|e| PyValueError::new_err(format!("conventions: {e}")))?,
        ..RenderOptions::default()
    })
}

/// The decision diagnostics as a dict of arrays (SPEC.md §8.1).
fn decisions_dict<'py>(py: Python<'py>, d: Decisions) -> PyResult<Bound<'py, PyDict>> {
    let (h, w, n) = (d.height, d.width, d.gaussian_flags.len());
    let out = PyDict::new(py);
    out.set_item("pixel_flags", to_numpy(py, d.pixel_flags, &[h, w])?)?;
    out.set_item("alpha_margin", to_numpy(py, d.alpha_margin, &[h, w])?)?;
    out.set_item(
        "transmittance_margin",
        to_numpy(py, d.transmittance_margin, &[h, w])?,
    )?;
    out.set_item("depth_margin", to_numpy(py, d.depth_margin, &[h, w])?)?;
    out.set_item("clamp_margin", to_numpy(py, d.clamp_margin, &[h, w])?)?;
    out.set_item("alpha_error", to_numpy(py, d.alpha_error, &[h, w])?)?;
    out.set_item("rgb_error", to_numpy(py, d.rgb_error, &[h, w])?)?;
    out.set_item("depth_error", to_numpy(py, d.depth_error, &[h, w])?)?;
    out.set_item("gaussian_flags", to_numpy(py, d.gaussian_flags, &[n])?)?;
    out.set_item(
        "conic_amplification",
        to_numpy(py, d.conic_amplification, &[n])?,
    )?;
    out.set_item("condition", to_numpy(py, d.condition, &[n])?)?;
    let m = PyDict::new(py);
    m.set_item("sigma", d.margins.sigma)?;
    m.set_item("alpha", d.margins.alpha)?;
    m.set_item("mean2d", d.margins.mean2d)?;
    m.set_item("transmittance", d.margins.transmittance)?;
    m.set_item("depth", d.margins.depth)?;
    m.set_item("recovery", d.margins.recovery)?;
    m.set_item("conic", d.margins.conic)?;
    out.set_item("margins", m)?;
    Ok(out)
}

/// Margins from an optional dict `{"sigma": .., "alpha": .., "mean2d": .., "transmittance": ..,
/// "depth": .., "recovery": .., "conic": ..}` (SPEC.md §8.1).
fn margins(d: Option<&Bound<'_, PyDict>>) -> PyResult<Margins> {
    let mut m = Margins::default();
    if let Some(d) = d {
        for (k, v) in d.iter() {
            let key: String = k.extract()?;
            let v: f32 = v.extract()?;
            match key.as_str() {
                "sigma" => m.sigma = v,
                "alpha" => m.alpha = v,
                "mean2d" => m.mean2d = v,
                "transmittance" => m.transmittance = v,
                "depth" => m.depth = v,
                "recovery" => m.recovery = v,
                "conic" => m.conic = v,
                _ => {
                    return Err(PyValueError::new_err(format!(
                        "margins: expected keys among 'sigma', 'alpha', 'mean2d', 'transmittance', 'depth', 'recovery', 'conic', got {key:?}"
                    )));
                }
            }
        }
    }
    Ok(m)
}

/// An `n × n` matrix of float64 or float32 (gsplat's dtype), as f64 (exact).
fn matrix(name: &str, obj: &Bound<'_, PyAny>, n: usize) -> PyResult<Vec<f64>> {
    let dims = [(Some(n), ""), (Some(n), "")];
    let is_f32 = obj
        .cast::<PyUntypedArray>()
        .is_ok_and(|a| a.dtype().is_equiv_to(&dtype::<f32>(obj.py())));
    if is_f32 {
        let (_, v) = array::<f32>(name, obj, &dims, &mut Vec::new())?;
        return Ok(v.into_iter().map(f64::from).collect());
    }
    array::<f64>(name, obj, &dims, &mut Vec::new())
        .map(|(_, v)| v)
        .map_err(|e| {
            PyValueError::new_err(
                e.to_string()
                    .replace("float64 array", "float64 (or float32) array"),
            )
        })
}

/// A pinhole camera (no distortion). Pixel centres are at `(j + 0.5, i + 0.5)`.
#[pyclass(frozen, name = "Camera", module = "unseen")]
#[derive(Clone)]
struct PyCamera {
    inner: Camera,
}

#[pymethods]
impl PyCamera {
    /// A camera from intrinsics `k` (3×3: fx, fy on the diagonal, cx, cy in the last column,
    /// no skew) and the world-to-camera matrix `viewmat` (4×4, last row 0 0 0 1), float64
    /// or float32 (gsplat's dtype; widened exactly), as gsplat takes them.
    #[new]
    #[pyo3(signature = (k, viewmat, width, height, name = "camera"))]
    fn new(
        k: &Bound<'_, PyAny>,
        viewmat: &Bound<'_, PyAny>,
        width: u32,
        height: u32,
        name: &str,
    ) -> PyResult<Self> {
        let k = matrix("k", k, 3)?;
        let v = matrix("viewmat", viewmat, 4)?;
        if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
            return Err(PyValueError::new_err(
                "k: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)",
            ));
        }
        if v[12] != 0.0 || v[13] != 0.0 || v[14] != 0.0 || v[15] != 1.0 {
            return Err(PyValueError::new_err(
                "viewmat: expected a rigid world-to-camera matrix with last row [0, 0, 0, 1]",
            ));
        }
        let r_cw = [[v[0], v[1], v[2]], [v[4], v[5], v[6]], [v[8], v[9], v[10]]];
        let t = [v[3], v[7], v[11]];
        let cam =
            Camera::from_world_to_camera(name, width, height, [k[0], k[4], k[2], k[5]], r_cw, t)
                .map_err(py_err)?;
        Ok(PyCamera { inner: cam })
    }

    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }
    #[getter]
    fn width(&self) -> u32 {
        self.inner.width
    }
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height
    }
    /// The 3×3 intrinsics (float64).
    #[getter]
    fn k<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let c = &self.inner;
        to_numpy(
            py,
            vec![c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0],
            &[3, 3],
        )
    }
    /// The 4×4 world-to-camera matrix (float64).
    #[getter]
    fn viewmat<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let r = self.inner.camera_from_world_rotation();
        let t = self.inner.camera_from_world_translation();
        let m = vec![
            r.x_axis.x, r.y_axis.x, r.z_axis.x, t.x, //
            r.x_axis.y, r.y_axis.y, r.z_axis.y, t.y, //
            r.x_axis.z, r.y_axis.z, r.z_axis.z, t.z, //
            0.0, 0.0, 0.0, 1.0,
        ];
        to_numpy(py, m, &[4, 4])
    }
    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "Camera(name={:?}, width={}, height={}, fx={}, fy={}, cx={}, cy={})",
            c.name, c.width, c.height, c.fx, c.fy, c.cx, c.cy
        )
    }
}

/// The cameras of an INRIA `cameras.json` (as `unseen oracle --cameras` reads them).
#[pyfunction]
fn load_cameras(py: Python<'_>, path: PathBuf) -> PyResult<Vec<PyCamera>> {
    let cams = py
        .detach(|| unseen::camera::inria::read_cameras_json(&path))
        .map_err(py_err)?;
    Ok(cams.into_iter().map(|inner| PyCamera { inner }).collect())
}

/// Render `camera` (see the module docs for the conventions). Returns a dict of arrays:
/// the images (`rgb` (H, W, 3), `alpha`, `depth`, `expected_depth`, `final_t`, `n_contrib`
/// (H, W)) and the forward's intermediates as `unseen oracle forward` dumps them
/// (`means2d`, `conics`, `depths`, `opacities`, `colors`, `radii`, `tile_offsets`,
/// `tile_ids`). `outputs` limits the images computed to some of `rgb`, `alpha`, `depth`,
/// `expected_depth` (then without `final_t` / `n_contrib`, which only the backward needs).
/// `inv_alpha_threshold` (255: gsplat's α ≥ 1/255; `inf`: every α > 0) and
/// `transmittance_stop` (1e-4) are the blend's cut-offs, a forward-only knob (SPEC.md §5.4).
#[pyfunction]
#[pyo3(signature = (means, quats, scales, opacities, sh, camera, *, sh_degree=None, background=[0.0, 0.0, 0.0], outputs=None, kernel="auto", threads=None, inv_alpha_threshold=255.0, transmittance_stop=1e-4, conventions="inria", diagnostics=false, margins=None))]
#[allow(clippy::too_many_arguments)]
fn render<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    scales: &Bound<'py, PyAny>,
    opacities: &Bound<'py, PyAny>,
    sh: &Bound<'py, PyAny>,
    camera: &PyCamera,
    sh_degree: Option<u32>,
    background: [f32; 3],
    outputs: Option<Vec<String>>,
    kernel: &str,
    threads: Option<usize>,
    inv_alpha_threshold: f32,
    transmittance_stop: f32,
    conventions: &str,
    diagnostics: bool,
    margins: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let g = scene(means, quats, scales, opacities, sh)?;
    let mut opts = options(background, sh_degree, kernel, conventions)?;
    let margins = self::margins(margins)?;
    // The forward cut-offs; the core checks them when it renders.
    opts.cutoffs = Cutoffs {
        inv_alpha_threshold,
        transmittance_stop,
    };
    opts.outputs = match &outputs {
        None => Outputs::ALL,
        Some(names) => {
            let mut o = Outputs {
                rgb: false,
                alpha: false,
                depth: false,
                expected_depth: false,
                backward_state: false,
            };
            for n in names {
                match n.as_str() {
                    "rgb" => o.rgb = true,
                    "alpha" => o.alpha = true,
                    "depth" => o.depth = true,
                    "expected_depth" => o.expected_depth = true,
                    _ => {
                        return Err(PyValueError::new_err(format!(
                            "outputs: expected names among 'rgb', 'alpha', 'depth', 'expected_depth', got {n:?}"
                        )));
                    }
                }
            }
            o
        }
    };
    let cam = &camera.inner;
    let ((render, projected, bins), diag) = py
        .detach(|| {
            unseen::sys::with_threads(threads, || {
                let plan = RenderPlan::new(&g, &opts);
                let staged = unseen::raster::render_staged(&g, cam, &opts, &plan)?;
                let diag = if diagnostics {
                    Some(decisions(&g, cam, &opts, &margins)?)
                } else {
                    None
                };
                Ok((staged, diag))
            })
        })
        .map_err(py_err)?
        .map_err(py_err)?;
    let (w, h, n) = (cam.width as usize, cam.height as usize, g.len());
    let d = PyDict::new(py);
    let image = |v: Option<Vec<f32>>, shape: &[usize]| -> PyResult<Option<Bound<'py, PyAny>>> {
        v.map(|v| to_numpy(py, v, shape)).transpose()
    };
    for (name, v, shape) in [
        ("rgb", render.rgb, vec![h, w, 3]),
        ("alpha", render.alpha, vec![h, w]),
        ("depth", render.depth, vec![h, w]),
        ("expected_depth", render.expected_depth, vec![h, w]),
        ("final_t", render.final_t, vec![h, w]),
    ] {
        if let Some(a) = image(v, &shape)? {
            d.set_item(name, a)?;
        }
    }
    if let Some(c) = render.n_contrib {
        d.set_item("n_contrib", to_numpy(py, c, &[h, w])?)?;
    }
    let s = &projected.splats;
    d.set_item(
        "means2d",
        to_numpy(py, s.iter().flat_map(|s| s.mean).collect(), &[n, 2])?,
    )?;
    d.set_item(
        "conics",
        to_numpy(py, s.iter().flat_map(|s| s.conic).collect(), &[n, 3])?,
    )?;
    d.set_item(
        "depths",
        to_numpy(py, s.iter().map(|s| s.depth).collect(), &[n])?,
    )?;
    d.set_item(
        "opacities",
        to_numpy(py, s.iter().map(|s| s.opacity).collect(), &[n])?,
    )?;
    d.set_item(
        "colors",
        to_numpy(py, s.iter().flat_map(|s| s.color).collect(), &[n, 3])?,
    )?;
    d.set_item(
        "radii",
        to_numpy(
            py,
            projected.radii.iter().flatten().copied().collect(),
            &[n, 2],
        )?,
    )?;
    let offsets: Vec<u64> = bins.offsets.iter().map(|&o| o as u64).collect();
    let len = offsets.len();
    d.set_item("tile_offsets", to_numpy(py, offsets, &[len])?)?;
    let len = bins.ids.len();
    d.set_item("tile_ids", to_numpy(py, bins.ids, &[len])?)?;
    if let Some(diag) = diag {
        d.set_item("diagnostics", decisions_dict(py, diag)?)?;
    }
    Ok(d)
}

/// Gradients of a loss with respect to every raw parameter, given the loss's gradients
/// with respect to the images (`grad_rgb` (H, W, 3); `grad_alpha`, `grad_depth`,
/// `grad_expected_depth` (H, W) optional). Returns a dict: `means` (N, 3), `quats`
/// (N, 4), `scales` (N, 3, log scales), `opacities` (N, logits), `sh` (N, K, 3),
/// `background` (3,), `means2d` (N, 2, pixels).
#[pyfunction]
#[pyo3(signature = (means, quats, scales, opacities, sh, camera, grad_rgb, *, grad_alpha=None, grad_depth=None, grad_expected_depth=None, sh_degree=None, background=[0.0, 0.0, 0.0], kernel="auto", threads=None, conventions="inria"))]
#[allow(clippy::too_many_arguments)]
fn backward<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    scales: &Bound<'py, PyAny>,
    opacities: &Bound<'py, PyAny>,
    sh: &Bound<'py, PyAny>,
    camera: &PyCamera,
    grad_rgb: &Bound<'py, PyAny>,
    grad_alpha: Option<&Bound<'py, PyAny>>,
    grad_depth: Option<&Bound<'py, PyAny>>,
    grad_expected_depth: Option<&Bound<'py, PyAny>>,
    sh_degree: Option<u32>,
    background: [f32; 3],
    kernel: &str,
    threads: Option<usize>,
    conventions: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let g = scene(means, quats, scales, opacities, sh)?;
    let mut opts = options(background, sh_degree, kernel, conventions)?;
    opts.outputs = Outputs::ALL;
    let cam = &camera.inner;
    let (h, w) = (cam.height as usize, cam.width as usize);
    let mut b = Vec::new();
    let plane = [(Some(h), "H"), (Some(w), "W")];
    let rgb = array::<f32>(
        "grad_rgb",
        grad_rgb,
        &[(Some(h), "H"), (Some(w), "W"), (Some(3), "")],
        &mut b,
    )?
    .1;
    let opt_plane = |name: &str, o: Option<&Bound<'py, PyAny>>, b: &mut Vec<(String, usize)>| {
        o.map(|a| array::<f32>(name, a, &plane, b).map(|x| x.1))
            .transpose()
    };
    let v = ImageGrads {
        rgb: Some(rgb),
        alpha: opt_plane("grad_alpha", grad_alpha, &mut b)?,
        depth: opt_plane("grad_depth", grad_depth, &mut b)?,
        expected_depth: opt_plane("grad_expected_depth", grad_expected_depth, &mut b)?,
    };
    let grads = py
        .detach(|| {
            unseen::sys::with_threads(threads, || {
                let fwd = unseen::raster::backward::render_for_backward(&g, cam, &opts)?;
                core_backward(&g, cam, &opts, &fwd, &v, &GradGroups::ALL)
            })
        })
        .map_err(py_err)?
        .map_err(py_err)?
        .0;
    let n = g.len();
    let k1 = g.rest_per_channel();
    let mut sh_grad = Vec::with_capacity(n * (k1 + 1) * 3);
    for (i, dc) in grads.sh_dc.iter().enumerate() {
        sh_grad.extend_from_slice(dc);
        sh_grad.extend_from_slice(&grads.sh_rest[i * k1 * 3..(i + 1) * k1 * 3]);
    }
    let d = PyDict::new(py);
    d.set_item("means", to_numpy(py, grads.means.concat(), &[n, 3])?)?;
    d.set_item("quats", to_numpy(py, grads.quats.concat(), &[n, 4])?)?;
    d.set_item("scales", to_numpy(py, grads.log_scales.concat(), &[n, 3])?)?;
    d.set_item("opacities", to_numpy(py, grads.opacity_logits, &[n])?)?;
    d.set_item("sh", to_numpy(py, sh_grad, &[n, k1 + 1, 3])?)?;
    d.set_item("background", to_numpy(py, grads.background.to_vec(), &[3])?)?;
    d.set_item("means2d", to_numpy(py, grads.means2d.concat(), &[n, 2])?)?;
    Ok(d)
}

/// A scene from an INRIA 3DGS PLY: a dict of `means`, `quats`, `scales`, `opacities`, `sh`
/// (gsplat conventions) and `sh_degree`.
#[pyfunction]
fn load_ply(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyDict>> {
    let (g, _) = py
        .detach(|| unseen::gaussian::ply::read_ply(&path))
        .map_err(py_err)?;
    scene_dict(py, g)
}

/// A scene as gsplat-convention arrays (`means`, `quats`, `scales`, `opacities`, `sh`) and
/// its `sh_degree`.
fn scene_dict(py: Python<'_>, g: Gaussians) -> PyResult<Bound<'_, PyDict>> {
    let n = g.len();
    let k = g.rest_per_channel() + 1;
    let mut sh = Vec::with_capacity(n * k * 3);
    for i in 0..n {
        sh.extend_from_slice(&g.sh_dc[i]);
        sh.extend_from_slice(g.rest(i));
    }
    let d = PyDict::new(py);
    d.set_item("means", to_numpy(py, g.means.concat(), &[n, 3])?)?;
    d.set_item("quats", to_numpy(py, g.quats.concat(), &[n, 4])?)?;
    d.set_item("scales", to_numpy(py, g.log_scales.concat(), &[n, 3])?)?;
    d.set_item("opacities", to_numpy(py, g.opacity_logits, &[n])?)?;
    d.set_item("sh", to_numpy(py, sh, &[n, k, 3])?)?;
    d.set_item("sh_degree", g.sh_degree)?;
    Ok(d)
}

/// Write a scene as an INRIA 3DGS PLY (atomically: no partial file on error).
#[pyfunction]
fn save_ply(
    py: Python<'_>,
    path: PathBuf,
    means: &Bound<'_, PyAny>,
    quats: &Bound<'_, PyAny>,
    scales: &Bound<'_, PyAny>,
    opacities: &Bound<'_, PyAny>,
    sh: &Bound<'_, PyAny>,
) -> PyResult<()> {
    let g = scene(means, quats, scales, opacities, sh)?;
    py.detach(|| unseen::gaussian::ply::write_ply(&g, &path))
        .map_err(py_err)
}

/// `unseen compare A B --tolerance T` as a JSON string (the package parses it).
#[pyfunction]
#[pyo3(signature = (run_a, run_b, tolerance=0.0))]
fn compare_json(
    py: Python<'_>,
    run_a: PathBuf,
    run_b: PathBuf,
    tolerance: f64,
) -> PyResult<String> {
    let c = py
        .detach(|| unseen::pipeline::compare::compare(&run_a, &run_b, tolerance))
        .map_err(py_err)?;
    Ok(serde_json::to_string(&c).expect("serializes"))
}

/// `unseen extrapolate`: the pipeline on a trained run. `config` is a JSON string of
/// overrides of the preset (as `--config` files hold). Returns the final scene's path (or
/// `None` for a run that stopped early) and the step names.
#[pyfunction]
#[pyo3(signature = (run, candidates, out, *, evaluation=None, dataset=None, preset="quick", config=None, resume=false, threads=None))]
#[allow(clippy::too_many_arguments)]
fn extrapolate(
    py: Python<'_>,
    run: PathBuf,
    candidates: PathBuf,
    out: PathBuf,
    evaluation: Option<PathBuf>,
    dataset: Option<PathBuf>,
    preset: &str,
    config: Option<String>,
    resume: bool,
    threads: Option<usize>,
) -> PyResult<(Option<PathBuf>, Vec<String>)> {
    let preset: unseen::pipeline::Preset = preset.parse().map_err(py_err)?;
    let cfg = match config {
        None => Ok(unseen::pipeline::config::PipelineConfig::preset(preset)),
        Some(text) => {
            let src = std::path::Path::new("<config argument>");
            serde_json::from_str(&text)
                .map_err(|e| Error::parse(src, format!("invalid JSON: {e}")))
                .and_then(|v| {
                    let c =
                        unseen::pipeline::config::PipelineConfig::with_overrides(preset, v, src)?;
                    c.validate().map_err(|e| e.at(src))?;
                    Ok(c)
                })
        }
    }
    .map_err(py_err)?;
    let outcome = py
        .detach(|| {
            unseen::sys::with_threads(threads, || {
                let inputs = unseen::pipeline::load_inputs(
                    &run,
                    &candidates,
                    evaluation.as_deref(),
                    dataset.as_deref(),
                )?;
                unseen::pipeline::run(&cfg, &inputs, &out, resume, &|_| {})
            })
        })
        .map_err(py_err)?
        .map_err(py_err)?;
    let steps = outcome.steps.iter().map(|s| s.name.clone()).collect();
    Ok((outcome.scene, steps))
}

/// Adam from zero moments on one float32 tensor (SPEC.md §14.2): `grads` holds one row per
/// step. `conventions` picks the constants: `"pytorch"` (`torch.optim.Adam`'s, with the
/// Python-float β; the default) or `"unseen"` (the trainer's update, the same bits).
/// Returns the parameters, `exp_avg` and `exp_avg_sq` after every step, each `(S, N)`.
#[pyfunction]
#[pyo3(signature = (params, grads, *, lr, betas = (0.9, 0.999), eps = 1e-15, conventions = "pytorch"))]
fn adam<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    grads: &Bound<'py, PyAny>,
    lr: f64,
    betas: (f64, f64),
    eps: f32,
    conventions: &str,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::train::adam::{Constants, adam_trace};
    let mut bound = Vec::new();
    let (_, x0) = array::<f32>("params", params, &[(None, "N")], &mut bound)?;
    let (shape, g) = array::<f32>("grads", grads, &[(None, "S"), (None, "N")], &mut bound)?;
    let constants = Constants::by_name(conventions)
        .map_err(|e| PyValueError::new_err(format!("conventions: {e}")))?;
    let trace = py
        .detach(|| adam_trace([betas.0, betas.1], eps, lr, constants, &x0, &g))
        .map_err(py_err)?;
    let out = PyDict::new(py);
    out.set_item("params", to_numpy(py, trace.x, &shape)?)?;
    out.set_item("exp_avg", to_numpy(py, trace.m, &shape)?)?;
    out.set_item("exp_avg_sq", to_numpy(py, trace.v, &shape)?)?;
    Ok(out)
}

/// The convex hull of a float64 `(N, 3)` point array, its errors naming the argument.
fn hull(name: &str, obj: &Bound<'_, PyAny>) -> PyResult<unseen::collide::gjk::ConvexHull> {
    let (_, v) = array::<f64>(name, obj, &[(None, "N"), (Some(3), "3")], &mut Vec::new())?;
    let points = v
        .chunks_exact(3)
        .map(|p| glam::DVec3::new(p[0], p[1], p[2]))
        .collect();
    unseen::collide::gjk::ConvexHull::new(points)
        .map_err(|e| PyValueError::new_err(format!("{name}: {e}")))
}

/// A list of non-negative indices (`name` in errors).
fn indices<T: TryFrom<i64>>(name: &str, v: &[i64]) -> PyResult<Vec<T>> {
    v.iter()
        .map(|&i| {
            T::try_from(i).map_err(|_| {
                PyValueError::new_err(format!("{name}: expected non-negative indices, got {i}"))
            })
        })
        .collect()
}

/// GJK proximity of the convex hulls of two point sets (SPEC.md §16.1), each float64
/// `(N, 3)`: `distance` (an upper bound), `lower_bound`, `intersect` (the verdict, on the
/// lower bound: touching within `touch_eps` collides) and `touch_eps`.
#[pyfunction]
fn proximity<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::collide::gjk::proximity as gjk;
    let (ha, hb) = (hull("a", a)?, hull("b", b)?);
    let p = py.detach(|| gjk(&ha, &hb)).map_err(py_err)?;
    let out = PyDict::new(py);
    out.set_item("distance", p.distance)?;
    out.set_item("lower_bound", p.lower_bound)?;
    out.set_item("intersect", p.intersect)?;
    out.set_item("touch_eps", p.touch_eps)?;
    Ok(out)
}

/// Scale-and-offset alignment `s·r + t ≈ m` of `estimate` (r) to the metric `depth` (m is
/// the depth or its inverse, `space`; SPEC.md §17), float32 `(N,)` each: `method`
/// `"ransac"` (relative `threshold`, at most `iterations`, adaptive stop at `confidence`,
/// `seed`) or `"least_squares"`. Returns scale, offset, inliers, valid, residual_mean and
/// residual_max.
#[pyfunction]
#[pyo3(signature = (estimate, depth, *, space = "disparity", method = "ransac", threshold = 0.05, iterations = 1000, confidence = Some(0.999), seed = 0))]
#[allow(clippy::too_many_arguments)]
fn align<'py>(
    py: Python<'py>,
    estimate: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    space: &str,
    method: &str,
    threshold: f64,
    iterations: u32,
    confidence: Option<f64>,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::warp::align::{Frame, RansacConfig, Space, least_squares, ransac};
    let mut bound = Vec::new();
    let (_, r) = array::<f32>("estimate", estimate, &[(None, "N")], &mut bound)?;
    let (_, d) = array::<f32>("depth", depth, &[(None, "N")], &mut bound)?;
    let space: Space = space
        .parse()
        .map_err(|e: Error| PyValueError::new_err(format!("space: {}", e.message)))?;
    let frames = [Frame {
        estimate: &r,
        depth: &d,
    }];
    let cfg = RansacConfig {
        threshold,
        iterations,
        confidence,
        seed,
    };
    let fit = match method {
        "ransac" => py.detach(|| ransac(&frames, space, &cfg)),
        "least_squares" => py.detach(|| least_squares(&frames, space)),
        other => {
            return Err(PyValueError::new_err(format!(
                "method: expected 'ransac' or 'least_squares', got {other:?}"
            )));
        }
    }
    .map_err(py_err)?;
    let out = PyDict::new(py);
    out.set_item("scale", fit.scale)?;
    out.set_item("offset", fit.offset)?;
    out.set_item("inliers", fit.inliers)?;
    out.set_item("valid", fit.valid)?;
    out.set_item("residual_mean", fit.residual_mean)?;
    out.set_item("residual_max", fit.residual_max)?;
    Ok(out)
}

/// SSIM of two float32 `(H, W, C)` images in [0, 1] (SPEC.md §13) under `conventions`:
/// `"inria"` (zero padding, the mean over every pixel: what training uses), `"valid"` (the
/// mean over the pixels whose window lies inside the image: pytorch-msssim) or `"reflect"`
/// (the images mirrored by the window's radius, the mean over every pixel: torchmetrics).
/// Returns `ssim`, `map` (the per-pixel mean over channels it averages: `(H, W)`, or
/// `(H − 10, W − 10)` for `"valid"`) and `l1`, the mean absolute difference; with
/// `gradient` (`"inria"`, 3 channels) also INRIA's `loss` (0.8·L1 + 0.2·(1 − SSIM)) and
/// its gradients `grad_ssim` = dSSIM/dx and `grad_loss` = dloss/dx.
#[pyfunction]
#[pyo3(signature = (x, y, *, conventions = "inria", gradient = false))]
fn ssim<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    conventions: &str,
    gradient: bool,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::train::ssim::{Border, ssim_border};
    let mut bound = Vec::new();
    let dims = [(None, "H"), (None, "W"), (None, "C")];
    let (shape, a) = array::<f32>("x", x, &dims, &mut bound)?;
    let (_, b) = array::<f32>("y", y, &dims, &mut bound)?;
    let (h, w, c) = (shape[0], shape[1], shape[2]);
    let border = match conventions {
        "inria" => Border::Zero,
        "valid" => Border::Valid,
        "reflect" => Border::Reflect,
        other => {
            return Err(PyValueError::new_err(format!(
                "conventions: expected 'inria', 'valid' or 'reflect', got {other:?}"
            )));
        }
    };
    let (value, map, map_shape) = py
        .detach(|| ssim_border(&a, &b, (w, h, c), border))
        .map_err(py_err)?;
    let l1 = unseen::train::loss::mean_abs_diff(&a, &b);
    let out = PyDict::new(py);
    out.set_item("ssim", value)?;
    out.set_item("map", to_numpy(py, map, &map_shape)?)?;
    out.set_item("l1", l1)?;
    if gradient {
        use unseen::train::loss::{LossInput, LossWeights, image_loss};
        if border != Border::Zero || c != 3 {
            return Err(PyValueError::new_err(
                "gradient: only for conventions 'inria' (the training loss) on 3 channels",
            ));
        }
        let (_, grad_ssim) = py.detach(|| unseen::train::ssim::ssim(&a, &b, w, h, c, true));
        let input = LossInput {
            width: w,
            height: h,
            rgb: &a,
            target_rgb: &b,
            depth: None,
            target_depth: None,
            mask: None,
        };
        let loss = py
            .detach(|| image_loss(&input, &LossWeights::INRIA))
            .map_err(py_err)?;
        out.set_item("loss", loss.terms.total)?;
        out.set_item(
            "grad_ssim",
            to_numpy(py, grad_ssim.unwrap_or_default(), &[h, w, c])?,
        )?;
        out.set_item("grad_loss", to_numpy(py, loss.grad_rgb, &[h, w, c])?)?;
    }
    Ok(out)
}

/// GMSD's maps of a render `x` against its truth `y`, float32 `(H, W, 3)` (SPEC.md §20.7,
/// `eval::GradientBlocks`): per 2 × 2 block `similarity`, `render_energy` and
/// `truth_energy` `(⌈H/2⌉, ⌈W/2⌉)`, and over the pixels of `mask` (bool `(H, W)`, default
/// every pixel) the pooled `gmsd` and `detail_ratio` and their `sums` (`weight`,
/// `gms_deficit` (Σ weight·(1 − similarity)), `gms_deficit_squares`,
/// `render_gradient_energy`, `truth_gradient_energy`).
#[pyfunction]
#[pyo3(signature = (x, y, *, mask = None))]
fn gradient_similarity<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    mask: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::pipeline::evaluate::ClassSums;
    let mut bound = Vec::new();
    let dims = [(None, "H"), (None, "W"), (Some(3), "3")];
    let (shape, a) = array::<f32>("x", x, &dims, &mut bound)?;
    let (_, b) = array::<f32>("y", y, &dims, &mut bound)?;
    let (h, w) = (shape[0], shape[1]);
    let m = match mask {
        Some(m) => array::<bool>("mask", m, &[(None, "H"), (None, "W")], &mut bound)?.1,
        None => vec![true; h * w],
    };
    let (g, sums) = py.detach(|| {
        let g = unseen::eval::GradientBlocks::new(&a, &b, w, h);
        let mut sums = ClassSums::default();
        for p in (0..w * h).filter(|&p| m[p]) {
            sums.add_gradients(&g, p % w, p / w, w, h);
        }
        (g, sums)
    });
    let out = PyDict::new(py);
    let half = [g.height, g.width];
    out.set_item("gmsd", ClassSums::gmsd([&sums]))?;
    out.set_item("detail_ratio", ClassSums::detail_ratio([&sums]))?;
    let s = PyDict::new(py);
    s.set_item("weight", sums.gms_weight)?;
    s.set_item("gms_deficit", sums.gms_deficit)?;
    s.set_item("gms_deficit_squares", sums.gms_deficit_squares)?;
    s.set_item("render_gradient_energy", sums.render_gradient_energy)?;
    s.set_item("truth_gradient_energy", sums.truth_gradient_energy)?;
    out.set_item("sums", s)?;
    out.set_item("similarity", to_numpy(py, g.similarity, &half)?)?;
    out.set_item("render_energy", to_numpy(py, g.render_energy, &half)?)?;
    out.set_item("truth_energy", to_numpy(py, g.truth_energy, &half)?)?;
    Ok(out)
}

/// Multi-view consistency (SPEC.md §21.7) of a render at camera `target` with the render at
/// camera `source` warped there: each render as RGB float32 `(H, W, 3)` (clamped to [0, 1]
/// by the caller), its alpha and its expected depth, float32 `(H, W)`. Returns float64 `(H,
/// W)`: per target pixel the squared colour difference summed over RGB where both renders
/// see one surface, NaN elsewhere.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn view_consistency<'py>(
    py: Python<'py>,
    source: &PyCamera,
    rgb: &Bound<'py, PyAny>,
    alpha: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    target: &PyCamera,
    target_rgb: &Bound<'py, PyAny>,
    target_alpha: &Bound<'py, PyAny>,
    target_depth: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    use unseen::eval::{DepthRender, consistency_errors};
    let (from, to) = (&source.inner, &target.inner);
    let read = |cam: &unseen::camera::Camera,
                names: [&str; 3],
                arrays: [&Bound<'py, PyAny>; 3]|
     -> PyResult<(Vec<f32>, Vec<f32>, Vec<f32>)> {
        let mut bound = vec![
            ("H".to_string(), cam.height as usize),
            ("W".to_string(), cam.width as usize),
        ];
        let image = [(None, "H"), (None, "W"), (Some(3), "3")];
        let (_, c) = array::<f32>(names[0], arrays[0], &image, &mut bound)?;
        let plane = [(None, "H"), (None, "W")];
        let (_, a) = array::<f32>(names[1], arrays[1], &plane, &mut bound)?;
        let (_, d) = array::<f32>(names[2], arrays[2], &plane, &mut bound)?;
        Ok((c, a, d))
    };
    let s = read(from, ["rgb", "alpha", "depth"], [rgb, alpha, depth])?;
    let t = read(
        to,
        ["target_rgb", "target_alpha", "target_depth"],
        [target_rgb, target_alpha, target_depth],
    )?;
    let errors = py
        .detach(|| {
            consistency_errors(
                DepthRender {
                    camera: from,
                    rgb: &s.0,
                    alpha: &s.1,
                    depth: &s.2,
                },
                DepthRender {
                    camera: to,
                    rgb: &t.0,
                    alpha: &t.1,
                    depth: &t.2,
                },
            )
        })
        .map_err(py_err)?;
    to_numpy(py, errors, &[to.height as usize, to.width as usize])
}

/// Telea inpainting (SPEC.md §19.1, OpenCV's `INPAINT_TELEA` arithmetic) of `image`, uint8
/// or float32 `(H, W, C)`, where the bool `(H, W)` `mask` is true, traced for a port's
/// comparison. With `forced` (a port's output, the image's shape and dtype) every fill
/// value is computed from the forced values of the pixels filled before it. Returns
/// `image`, `time` and `order` `(H, W)` (fill order, −1 for known pixels), and per value
/// `mean`, `term` (the value is `mean + term`, rounded for uint8), `bound` and `aside`.
#[pyfunction]
#[pyo3(signature = (image, mask, *, radius = 3.0, forced = None))]
fn inpaint<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    mask: &Bound<'py, PyAny>,
    radius: f64,
    forced: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::models::telea::{Sample, Trace, inpaint_traced};
    fn run<'py, T: Sample + numpy::Element>(
        py: Python<'py>,
        image: &Bound<'py, PyAny>,
        mask: &Bound<'py, PyAny>,
        radius: f64,
        forced: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<(Vec<usize>, Trace<T>)> {
        let mut bound = Vec::new();
        let dims = [(None, "H"), (None, "W"), (None, "C")];
        let (shape, img) = array::<T>("image", image, &dims, &mut bound)?;
        let (_, m) = array::<bool>("mask", mask, &[(None, "H"), (None, "W")], &mut bound)?;
        let forced = match forced {
            Some(f) => Some(array::<T>("forced", f, &dims, &mut bound)?.1),
            None => None,
        };
        let (h, w, c) = (shape[0], shape[1], shape[2]);
        let trace = py
            .detach(|| inpaint_traced(&img, w, h, c, &m, radius, forced.as_deref()))
            .map_err(py_err)?;
        Ok((shape, trace))
    }
    let out = PyDict::new(py);
    let dtype_is = |d: Bound<'py, numpy::PyArrayDescr>| {
        image
            .cast::<PyUntypedArray>()
            .is_ok_and(|a| a.dtype().is_equiv_to(&d))
    };
    let is_u8 = dtype_is(numpy::dtype::<u8>(py));
    if !is_u8 && !dtype_is(numpy::dtype::<f32>(py)) {
        return Err(PyValueError::new_err(
            "image: expected a C-contiguous uint8 or float32 array of shape (H, W, C)",
        ));
    }
    let (shape, rest) = if is_u8 {
        let (shape, t) = run::<u8>(py, image, mask, radius, forced)?;
        out.set_item("image", to_numpy(py, t.image, &shape)?)?;
        (shape, (t.time, t.order, t.mean, t.term, t.bound, t.aside))
    } else {
        let (shape, t) = run::<f32>(py, image, mask, radius, forced)?;
        out.set_item("image", to_numpy(py, t.image, &shape)?)?;
        (shape, (t.time, t.order, t.mean, t.term, t.bound, t.aside))
    };
    let (time, order, mean, term, bound, aside) = rest;
    out.set_item("time", to_numpy(py, time, &shape[..2])?)?;
    out.set_item("order", to_numpy(py, order, &shape[..2])?)?;
    out.set_item("mean", to_numpy(py, mean, &shape)?)?;
    out.set_item("term", to_numpy(py, term, &shape)?)?;
    out.set_item("bound", to_numpy(py, bound, &shape)?)?;
    out.set_item("aside", to_numpy(py, aside, &shape)?)?;
    Ok(out)
}

/// The frustum of `camera`'s region `mask` (bool `(H, W)`, the camera's size; SPEC.md
/// §16.3) between camera depths `near` and `far`, or the valid depths' `[min, max]` under
/// the mask of `depth` (float32 `(H, W)`); `outline` `"bounding_box"` (the paper's) or
/// `"hull"`. Returns `vertices` (float64 `(V, 3)`: the near outline, then the far one),
/// `faces` (outward, counter-clockwise vertex lists), `near` and `far`.
#[pyfunction]
#[pyo3(signature = (camera, mask, *, depth = None, near = None, far = None, outline = "bounding_box"))]
fn frustum<'py>(
    py: Python<'py>,
    camera: &PyCamera,
    mask: &Bound<'py, PyAny>,
    depth: Option<&Bound<'py, PyAny>>,
    near: Option<f64>,
    far: Option<f64>,
    outline: &str,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::collide::frustum::{Outline, depth_range, region_frustum};
    let cam = &camera.inner;
    let dims = [
        (Some(cam.height as usize), "H"),
        (Some(cam.width as usize), "W"),
    ];
    let mut bound = Vec::new();
    let (_, m) = array::<bool>("mask", mask, &dims, &mut bound)?;
    let outline: Outline = outline
        .parse()
        .map_err(|e: Error| PyValueError::new_err(format!("outline: {}", e.message)))?;
    let range = match (depth, near, far) {
        (Some(d), None, None) => {
            let (_, d) = array::<f32>("depth", d, &dims, &mut bound)?;
            depth_range(&d, &m).map_err(py_err)?
        }
        (None, Some(n), Some(f)) => [n, f],
        _ => {
            return Err(PyValueError::new_err(
                "give either depth or both near and far",
            ));
        }
    };
    let p = py
        .detach(|| region_frustum(cam, &m, range, outline))
        .map_err(py_err)?;
    let out = PyDict::new(py);
    let flat: Vec<f64> = p.vertices.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
    out.set_item("vertices", to_numpy(py, flat, &[p.vertices.len(), 3])?)?;
    out.set_item("faces", p.faces)?;
    out.set_item("near", range[0])?;
    out.set_item("far", range[1])?;
    Ok(out)
}

/// Independent views (SPEC.md §16.2) of candidate frustums (a list of float64 `(V, 3)`
/// vertex arrays) with camera `centers` (float64 `(n, 3)`): the collision graph (or the
/// given `edges`, pairs `i < j`), the independent set greedy in `order` (default the given
/// order) and the closed nearest-neighbour tour. Returns `edges`, `independent`,
/// `trajectory` and `gaps`.
#[pyfunction]
#[pyo3(signature = (frustums, centers, *, order = None, edges = None))]
fn views<'py>(
    py: Python<'py>,
    frustums: Vec<Bound<'py, PyAny>>,
    centers: &Bound<'py, PyAny>,
    order: Option<Vec<i64>>,
    edges: Option<Vec<(i64, i64)>>,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::collide::independent::{select, select_in_graph};
    let n = frustums.len();
    let (_, c) = array::<f64>(
        "centers",
        centers,
        &[(Some(n), "n"), (Some(3), "3")],
        &mut Vec::new(),
    )?;
    if c.iter().any(|v| !v.is_finite()) {
        return Err(PyValueError::new_err(
            "centers: every coordinate must be finite",
        ));
    }
    let centers: Vec<glam::DVec3> = c
        .chunks_exact(3)
        .map(|p| glam::DVec3::new(p[0], p[1], p[2]))
        .collect();
    let order: Option<Vec<usize>> = order.map(|o| indices("order", &o)).transpose()?;
    let hulls = frustums
        .iter()
        .enumerate()
        .map(|(k, f)| hull(&format!("frustums[{k}]"), f))
        .collect::<PyResult<Vec<_>>>()?;
    let sel = match edges {
        Some(e) => {
            let flat: Vec<i64> = e.iter().flat_map(|&(i, j)| [i, j]).collect();
            let pairs: Vec<usize> = indices("edges", &flat)?;
            let pairs = pairs.chunks_exact(2).map(|p| (p[0], p[1])).collect();
            py.detach(|| select_in_graph(n, pairs, &centers, order.as_deref()))
        }
        None => py.detach(|| select(&hulls, &centers, order.as_deref())),
    }
    .map_err(py_err)?;
    let out = PyDict::new(py);
    out.set_item("edges", sel.edges)?;
    out.set_item("independent", sel.independent)?;
    out.set_item("trajectory", sel.trajectory)?;
    out.set_item("gaps", sel.gaps)?;
    Ok(out)
}

/// DIBR forward warp (SPEC.md §18) of `image` (float32 `(H, W, C)`) with its camera-z
/// `depth` (float32 `(H, W)`) from camera `source` to camera `target`, traced for a
/// port's comparison. Returns `image`, `depth` and `holes` (the target's size), the source
/// pixels' projections `u`, `v` (float64) and `z` (float32; NaN when invalid or behind),
/// per target pixel `aside` (the decisions within a port's float noise) and `stats`.
#[pyfunction]
#[pyo3(signature = (image, depth, source, target, *, footprint = "nearest", depth_tolerance = 0.01, close_cracks = 0, grow_holes = 0))]
#[allow(clippy::too_many_arguments)]
fn warp<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    depth: &Bound<'py, PyAny>,
    source: &PyCamera,
    target: &PyCamera,
    footprint: &str,
    depth_tolerance: f32,
    close_cracks: i64,
    grow_holes: i64,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::io::image::ImageF32;
    let radius = |name: &str, r: i64| {
        u32::try_from(r).map_err(|_| {
            PyValueError::new_err(format!("{name}: expected a non-negative radius, got {r}"))
        })
    };
    let (close_cracks, grow_holes) = (
        radius("close_cracks", close_cracks)?,
        radius("grow_holes", grow_holes)?,
    );
    use unseen::warp::dibr::{Footprint, WarpOptions, warp_traced};
    let (from, to) = (&source.inner, &target.inner);
    let (h, w) = (from.height as usize, from.width as usize);
    let mut bound = vec![("H".to_string(), h), ("W".to_string(), w)];
    let (shape, img) = array::<f32>(
        "image",
        image,
        &[(None, "H"), (None, "W"), (None, "C")],
        &mut bound,
    )?;
    let (_, d) = array::<f32>("depth", depth, &[(None, "H"), (None, "W")], &mut bound)?;
    if shape[2] == 0 {
        return Err(PyValueError::new_err(
            "image: expected at least one channel",
        ));
    }
    let footprint: Footprint = footprint
        .parse()
        .map_err(|e: Error| PyValueError::new_err(format!("footprint: {}", e.message)))?;
    let opts = WarpOptions {
        footprint,
        depth_tolerance,
        close_cracks,
        grow_holes,
    };
    let img = ImageF32::new(w, h, shape[2], img).map_err(py_err)?;
    let t = py
        .detach(|| warp_traced(&img, &d, from, to, &opts))
        .map_err(py_err)?;
    let (tw, th, ch) = (to.width as usize, to.height as usize, shape[2]);
    let out = PyDict::new(py);
    out.set_item("image", to_numpy(py, t.warped.image.data, &[th, tw, ch])?)?;
    out.set_item("depth", to_numpy(py, t.warped.depth, &[th, tw])?)?;
    out.set_item("holes", to_numpy(py, t.warped.holes, &[th, tw])?)?;
    out.set_item("u", to_numpy(py, t.u, &[h, w])?)?;
    out.set_item("v", to_numpy(py, t.v, &[h, w])?)?;
    out.set_item("z", to_numpy(py, t.z, &[h, w])?)?;
    out.set_item("aside", to_numpy(py, t.aside, &[th, tw])?)?;
    let stats = PyDict::new(py);
    let st = t.warped.stats;
    for (k, v) in [
        ("invalid_depth", st.invalid_depth),
        ("behind_target", st.behind_target),
        ("outside_target", st.outside_target),
        ("raw_holes", st.raw_holes),
        ("cracks_filled", st.cracks_filled),
        ("grown", st.grown),
    ] {
        stats.set_item(k, v)?;
    }
    out.set_item("stats", stats)?;
    Ok(out)
}

/// One densify-and-prune step (SPEC.md §14.3) on a scene of gsplat-convention arrays with
/// its gradient statistics (`grad_accum`: the sum over visible views of `|dL/d mean2d|` in
/// NDC units, float32 `(N,)`; `count`: those views, uint32 `(N,)`), the scene `extent`,
/// `world_prune` (the large-Gaussian test, on after the first opacity reset) and the split
/// children's `normals` (float32 `(2, N, 3)`: copy `c` of Gaussian `i` takes
/// `normals[c, i]`). Returns the new scene's arrays and `cloned`, `split`, `pruned`.
#[pyfunction]
#[pyo3(signature = (means, quats, scales, opacities, sh, grad_accum, count, *, extent, world_prune, normals, grad_threshold = 2e-4, percent_dense = 0.01, min_opacity = 0.005, world_prune_fraction = 0.1))]
#[allow(clippy::too_many_arguments)]
fn densify<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    scales: &Bound<'py, PyAny>,
    opacities: &Bound<'py, PyAny>,
    sh: &Bound<'py, PyAny>,
    grad_accum: &Bound<'py, PyAny>,
    count: &Bound<'py, PyAny>,
    extent: f32,
    world_prune: bool,
    normals: &Bound<'py, PyAny>,
    grad_threshold: f32,
    percent_dense: f32,
    min_opacity: f32,
    world_prune_fraction: f32,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::train::densify::{DensifyConfig, densify_given};
    let mut g = scene(means, quats, scales, opacities, sh)?;
    let n = g.len();
    let mut b = vec![("N".to_string(), n)];
    let (_, acc) = array::<f32>("grad_accum", grad_accum, &[(None, "N")], &mut b)?;
    let (_, cnt) = array::<u32>("count", count, &[(None, "N")], &mut b)?;
    let (_, z) = array::<f32>(
        "normals",
        normals,
        &[(Some(2), "2"), (None, "N"), (Some(3), "3")],
        &mut b,
    )?;
    if !(extent.is_finite() && extent > 0.0) {
        return Err(PyValueError::new_err(format!(
            "extent: expected a finite positive number, got {extent}"
        )));
    }
    let cfg = DensifyConfig {
        grad_threshold,
        percent_dense,
        min_opacity,
        world_prune_fraction,
        ..DensifyConfig::default()
    };
    let z = triples(&z);
    let report = py
        .detach(|| densify_given(&mut g, (acc, cnt), &cfg, extent, world_prune, &z))
        .map_err(py_err)?;
    let out = scene_dict(py, g)?;
    out.set_item("cloned", report.cloned)?;
    out.set_item("split", report.split)?;
    out.set_item("pruned", report.pruned)?;
    Ok(out)
}

/// The QA-Mask (SPEC.md §15.1) for ports. With `camera`: the mask of a (fine-tuned) mask
/// scene, rendered over `base` and projected on the base–target colour axis (`mask`,
/// `(H, W)`). Without: the mask scene built from a trained one (same geometry, SH DC the
/// `base` colour, zero higher coefficients at `sh_degree`), as arrays.
#[pyfunction]
#[pyo3(signature = (means, quats, scales, opacities, sh, camera = None, *, base = [1.0, 0.0, 0.0], target = [0.0, 0.0, 0.0], sh_degree = 5))]
#[allow(clippy::too_many_arguments)]
fn qa_mask<'py>(
    py: Python<'py>,
    means: &Bound<'py, PyAny>,
    quats: &Bound<'py, PyAny>,
    scales: &Bound<'py, PyAny>,
    opacities: &Bound<'py, PyAny>,
    sh: &Bound<'py, PyAny>,
    camera: Option<&PyCamera>,
    base: [f32; 3],
    target: [f32; 3],
    sh_degree: u32,
) -> PyResult<Bound<'py, PyDict>> {
    use unseen::qamask::{QaMaskConfig, mask_scene, render_qa_mask};
    let g = scene(means, quats, scales, opacities, sh)?;
    let cfg = QaMaskConfig {
        sh_degree,
        base_color: base,
        target_color: target,
        ..QaMaskConfig::default()
    };
    match camera {
        Some(cam) => {
            let (w, h) = (cam.inner.width as usize, cam.inner.height as usize);
            let mask = py
                .detach(|| {
                    cfg.validate()?;
                    render_qa_mask(&g, &cam.inner, &cfg)
                })
                .map_err(py_err)?;
            let out = PyDict::new(py);
            out.set_item("mask", to_numpy(py, mask, &[h, w])?)?;
            Ok(out)
        }
        None => {
            let m = py.detach(|| mask_scene(&g, &cfg)).map_err(py_err)?;
            scene_dict(py, m)
        }
    }
}

/// The crate version, SPEC.md's conventions version and the numerics revision (a port
/// records them beside its goldens).
#[pyfunction]
fn versions() -> (String, u32, u32) {
    (
        unseen::VERSION.to_string(),
        unseen::version::CONVENTIONS_VERSION,
        unseen::version::NUMERICS_REVISION,
    )
}

#[pymodule]
fn _unseen(m: &Bound<'_, PyModule>) -> PyResult<()> {
    unseen::sys::init_global_pool();
    m.add_class::<PyCamera>()?;
    m.add_function(wrap_pyfunction!(load_cameras, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(backward, m)?)?;
    m.add_function(wrap_pyfunction!(load_ply, m)?)?;
    m.add_function(wrap_pyfunction!(save_ply, m)?)?;
    m.add_function(wrap_pyfunction!(compare_json, m)?)?;
    m.add_function(wrap_pyfunction!(extrapolate, m)?)?;
    m.add_function(wrap_pyfunction!(versions, m)?)?;
    m.add_function(wrap_pyfunction!(adam, m)?)?;
    m.add_function(wrap_pyfunction!(proximity, m)?)?;
    m.add_function(wrap_pyfunction!(align, m)?)?;
    m.add_function(wrap_pyfunction!(ssim, m)?)?;
    m.add_function(wrap_pyfunction!(gradient_similarity, m)?)?;
    m.add_function(wrap_pyfunction!(view_consistency, m)?)?;
    m.add_function(wrap_pyfunction!(inpaint, m)?)?;
    m.add_function(wrap_pyfunction!(frustum, m)?)?;
    m.add_function(wrap_pyfunction!(views, m)?)?;
    m.add_function(wrap_pyfunction!(warp, m)?)?;
    m.add_function(wrap_pyfunction!(densify, m)?)?;
    m.add_function(wrap_pyfunction!(qa_mask, m)?)?;
    Ok(())
}
