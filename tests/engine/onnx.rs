//! ONNX models through tract against `onnx.reference.ReferenceEvaluator`
//! (`reference_data/onnx/`, made by `make_onnx_goldens.py`): raw tensors, the adapter's
//! whole image path, determinism, and clear errors for malformed or mismatched models.

use crate::support::{bits, reference, with_threads};
use unseen::io::image::ImageF32;
use unseen::io::npy::read_npy_f32;
use unseen::models::onnx::{OnnxDepth, OnnxFixer, OnnxInpainter, OnnxModel};
use unseen::models::{ArtifactFixer, DepthEstimator, DepthKind, Inpainter};

/// `|a − b| ≤ ONNX_TOL·max(1, max|b|)` over a tensor: the 1e-5, scaled by the
/// tensor's peak when it exceeds 1. tract sums convolutions in another order than the
/// reference evaluator and evaluates Sigmoid with a rational approximation (~1e-7 of its
/// range), so the inpainting model's `255·sigmoid` differs by up to 1.25e-5 absolute at
/// values near 0 (5e-8 of the output's range).
const ONNX_TOL: f32 = 1e-5;

fn npy(case: &str, name: &str) -> (Vec<usize>, Vec<f32>) {
    read_npy_f32(&reference(&format!("onnx/{case}/{name}.npy"))).unwrap()
}

/// The largest `|a − b|` relative to `max(1, max|b|)`.
fn close(got: &[f32], want: &[f32]) -> f32 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(1f32, |m, b| m.max(b.abs()));
    got.iter()
        .zip(want)
        .map(|(a, b)| (a - b).abs() / scale)
        .fold(0.0, f32::max)
}

#[test]
fn onnx_tiny_models_match_the_reference_evaluator() {
    for (case, inputs) in [
        ("depth_tiny", vec!["image"]),
        ("inpaint_tiny", vec!["image", "mask"]),
        ("fixer_nhwc", vec!["image"]),
    ] {
        let m = OnnxModel::load(&reference(&format!("onnx/{case}/card.json"))).unwrap();
        let ins: Vec<(Vec<usize>, Vec<f32>)> = inputs
            .iter()
            .map(|n| npy(case, &format!("input_{n}")))
            .collect();
        let (want_shape, want) = npy(case, "expected");
        let (shape, got) = m.run_tensors(&ins).unwrap();
        assert_eq!(shape, want_shape, "{case}");
        let err = close(&got, &want);
        println!("{case}: max relative error {err:e}");
        assert!(err <= ONNX_TOL, "{case}: {err:e}");
        // Bit-identical across runs and thread counts.
        let again = with_threads(1, || m.run_tensors(&ins).unwrap().1);
        let two = with_threads(2, || m.run_tensors(&ins).unwrap().1);
        assert_eq!(bits(&got), bits(&again));
        assert_eq!(bits(&got), bits(&two));
    }
}

/// The adapter's image path (resize to the card's size, ImageNet normalization, NCHW,
/// model, resize back) against cv2.resize + the reference evaluator.
#[test]
fn onnx_depth_adapter_matches_opencv_and_the_evaluator() {
    let d = OnnxDepth::load(&reference("onnx/depth_e2e/card.json")).unwrap();
    let (shape, data) = npy("depth_e2e", "input_image");
    let img = ImageF32::new(shape[1], shape[0], shape[2], data).unwrap();
    let out = d.estimate(&img, None).unwrap();
    assert_eq!(
        (out.width, out.height, out.kind),
        (20, 15, DepthKind::Disparity)
    );
    let (_, want) = npy("depth_e2e", "expected");
    let err = close(&out.values, &want);
    println!("depth_e2e: max relative error {err:e}");
    assert!(err <= ONNX_TOL, "{err:e}");
    // Slot adapters on the other tiny models: known pixels stay exact when inpainting,
    // the fixer returns an image of the render's size.
    let inp = OnnxInpainter::load(&reference("onnx/inpaint_tiny/card.json")).unwrap();
    let (_, px) = npy("inpaint_tiny", "input_image");
    let rgb: Vec<f32> = (0..256)
        .flat_map(|p| [px[p], px[256 + p], px[512 + p]])
        .collect();
    let img = ImageF32::new(16, 16, 3, rgb).unwrap();
    let mask: Vec<bool> = (0..256).map(|p| p % 7 == 0).collect();
    let r = inp.inpaint(&img, &mask).unwrap();
    for (p, &m) in mask.iter().enumerate() {
        if !m {
            assert_eq!(&r.data[3 * p..3 * p + 3], &img.data[3 * p..3 * p + 3]);
        } else {
            assert!(
                r.data[3 * p..3 * p + 3]
                    .iter()
                    .all(|v| (0.0..=1.0).contains(v))
            );
        }
    }
    let fx = OnnxFixer::load(&reference("onnx/fixer_nhwc/card.json")).unwrap();
    let small = ImageF32::new(9, 7, 3, vec![0.5; 9 * 7 * 3]).unwrap();
    let f = fx.fix(&small, None).unwrap();
    assert_eq!((f.width, f.height, f.channels), (9, 7, 3));
}

#[test]
fn onnx_errors_name_the_file_and_the_mismatch() {
    let dir = crate::support::TempDir::new("onnx");
    let err = |card: &std::path::Path| OnnxModel::load(card).err().unwrap().to_string();
    // Rank-3 image input.
    let e = err(&reference("onnx/bad_rank/card.json"));
    assert!(
        e.contains("bad_rank/model.onnx") && e.contains("rank 3"),
        "{e}"
    );
    // Not ONNX.
    std::fs::write(dir.join("junk.onnx"), "this is not a protobuf").unwrap();
    let card = |model: &str, output: &str, input: &str| {
        serde_json::json!({
            "model": model, "inputs": {"image": input}, "output": output, "layout": "nchw",
            "size": {"policy": "native"}, "resize": "bilinear", "input_range": [0.0, 1.0],
            "mean": [], "std": [], "output_kind": "depth"
        })
        .to_string()
    };
    std::fs::write(dir.join("junk.json"), card("junk.onnx", "depth", "image")).unwrap();
    let e = err(&dir.join("junk.json"));
    assert!(e.contains("junk.onnx") && e.contains("ONNX"), "{e}");
    // Missing output and input names.
    let model = reference("onnx/depth_tiny/model.onnx");
    std::fs::copy(&model, dir.join("m.onnx")).unwrap();
    std::fs::write(dir.join("no_out.json"), card("m.onnx", "nope", "image")).unwrap();
    let e = err(&dir.join("no_out.json"));
    assert!(
        e.contains("m.onnx") && e.contains("no output 'nope'"),
        "{e}"
    );
    std::fs::write(dir.join("no_in.json"), card("m.onnx", "depth", "rgb")).unwrap();
    let e = err(&dir.join("no_in.json"));
    assert!(e.contains("no input 'rgb'") && e.contains("image"), "{e}");
    // Missing model file, malformed card.
    std::fs::write(dir.join("gone.json"), card("gone.onnx", "depth", "image")).unwrap();
    assert!(err(&dir.join("gone.json")).contains("gone.onnx"));
    std::fs::write(dir.join("bad.json"), "{\"model\": 3}").unwrap();
    assert!(err(&dir.join("bad.json")).contains("bad.json"));
    // A depth card cannot serve as an inpainter.
    let e = OnnxInpainter::load(&reference("onnx/depth_tiny/card.json"))
        .err()
        .unwrap();
    assert!(e.to_string().contains("inpainting"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// tract 0.21's `Resize(linear, half_pixel)` does not clamp source coordinates below 0, so
/// the first output row and column of an upsampling extrapolate where the ONNX reference
/// clamps (found here; no upstream report yet). Every other value agrees; the edge
/// difference is printed so an upgrade that fixes it shows up.
#[test]
fn onnx_resize_half_pixel_agrees_off_the_low_edge() {
    let m = OnnxModel::load(&reference("onnx/resize_half/card.json")).unwrap();
    let x = npy("resize_half", "input_image");
    let (shape, want) = npy("resize_half", "expected");
    let (got_shape, got) = m.run_tensors(&[x]).unwrap();
    assert_eq!(got_shape, shape);
    let (h, w) = (shape[2], shape[3]);
    let (mut inner, mut edge) = (0f32, 0f32);
    let scale = want.iter().fold(1f32, |m, b| m.max(b.abs()));
    for (i, (a, b)) in got.iter().zip(&want).enumerate() {
        let (y, x) = ((i / w) % h, i % w);
        let d = (a - b).abs() / scale;
        if y == 0 || x == 0 {
            edge = edge.max(d);
        } else {
            inner = inner.max(d);
        }
    }
    println!("resize_half: interior {inner:e}, first row/column {edge:e}");
    assert!(inner <= ONNX_TOL, "{inner:e}");
}

/// `io::image::resize` against `cv2.resize` (float32, INTER_LINEAR / INTER_CUBIC, up and
/// down; `reference_data/opencv/resize/`): within `RESIZE_TOL` (f32 rounding: OpenCV's
/// float path sums the same taps in the same order but rounds its weights differently).
#[test]
fn resize_matches_opencv() {
    const RESIZE_TOL: f32 = 1e-5;
    for dir in crate::support::case_dirs("opencv/resize") {
        #[derive(serde::Deserialize)]
        struct Case {
            filter: unseen::io::image::Filter,
            width: usize,
            height: usize,
        }
        let c: Case =
            serde_json::from_str(&std::fs::read_to_string(dir.join("case.json")).unwrap()).unwrap();
        let (s, data) = read_npy_f32(&dir.join("input.npy")).unwrap();
        let (ws, want) = read_npy_f32(&dir.join("expected.npy")).unwrap();
        let img = ImageF32::new(s[1], s[0], s[2], data).unwrap();
        let got = unseen::io::image::resize(&img, c.width, c.height, c.filter).unwrap();
        assert_eq!((got.height, got.width, got.channels), (ws[0], ws[1], ws[2]));
        let err = got
            .data
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        println!("{}: max error {err:e}", dir.display());
        assert!(err <= RESIZE_TOL, "{}: {err:e}", dir.display());
    }
}
