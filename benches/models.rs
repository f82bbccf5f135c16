//! Model-slot timings: `cargo bench --bench models`.
//!
//! - Telea, 512×512 RGB 8-bit, a 10 % mask of blobs, radius 3 (best of 5, one thread: the
//!   march is sequential), and OpenCV's `cv2.inpaint` on the same bytes in the same run
//!   when a Python with cv2 is available (`UNSEEN_PYTHON`, default `python3`; skipped
//!   otherwise).
//! - `morph`: per intermediate frame at 256×256 (two DIBR warps, blend, Telea fill).
//! - tract: a user-provided Depth-Anything-sized model, when `UNSEEN_DEPTH_CARD` names its
//!   card (skipped otherwise).

mod common;

use common::best;
use glam::{DMat3, DVec3};
use unseen::camera::Camera;
use unseen::io::image::{ImageF32, write_png};
use unseen::models::morph::Morph;
use unseen::models::telea::inpaint;
use unseen::models::{Keyframe, VideoGenerator};
use unseen::rng::Uniform;

fn blob_mask(w: usize, h: usize, target: f64, u: &mut Uniform) -> Vec<bool> {
    let mut m = vec![false; w * h];
    while (m.iter().filter(|&&b| b).count() as f64) < target * (w * h) as f64 {
        let (cx, cy, r) = (
            u.unit() * w as f32,
            u.unit() * h as f32,
            6.0 + u.unit() * 24.0,
        );
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                if dx * dx + dy * dy < r * r {
                    m[y * w + x] = true;
                }
            }
        }
    }
    m
}

fn telea() {
    let (w, h) = (512usize, 512usize);
    let mut u = Uniform::new(9);
    // A smooth texture with edges, like a render.
    let img: Vec<u8> = (0..w * h * 3)
        .map(|i| {
            let (p, c) = (i / 3, i % 3);
            let (x, y) = ((p % w) as f32, (p / w) as f32);
            let v = 0.5
                + 0.3 * (x * 0.05 + c as f32).sin() * (y * 0.03).cos()
                + 0.2 * ((x + y) > 500.0) as i32 as f32;
            (v.clamp(0.0, 1.0) * 255.0) as u8
        })
        .collect();
    let mask = blob_mask(w, h, 0.10, &mut u);
    let frac = mask.iter().filter(|&&b| b).count() as f64 / (w * h) as f64;
    let (ours, _) = best(5, || {
        inpaint(&img, w, h, 3, &mask, 3.0).unwrap();
    });
    println!(
        "Telea 512x512 RGB, {:.1} % mask, radius 3: ours {:.1} ms",
        100.0 * frac,
        ours * 1e3
    );
    let dir = std::env::temp_dir().join(format!("unseen-bench-telea-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = |v: &[u8], c| {
        ImageF32::new(w, h, c, v.iter().map(|&b| b as f32 / 255.0).collect()).unwrap()
    };
    write_png(&dir.join("img.png"), &f(&img, 3)).unwrap();
    let mbytes: Vec<u8> = mask.iter().map(|&b| if b { 255 } else { 0 }).collect();
    write_png(&dir.join("mask.png"), &f(&mbytes, 1)).unwrap();
    let py = std::env::var("UNSEEN_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = format!(
        "import cv2, time\ni=cv2.imread(r'{}'); m=cv2.imread(r'{}', 0)\nb=1e9\nfor _ in range(5):\n t=time.perf_counter(); cv2.inpaint(i, m, 3, cv2.INPAINT_TELEA); b=min(b, time.perf_counter()-t)\nprint(cv2.__version__, b)",
        dir.join("img.png").display(),
        dir.join("mask.png").display()
    );
    match std::process::Command::new(&py)
        .args(["-c", &script])
        .output()
    {
        Ok(o) if o.status.success() => {
            let s = String::from_utf8_lossy(&o.stdout);
            let mut it = s.split_whitespace();
            let (ver, t): (&str, f64) = (
                it.next().unwrap_or("?"),
                it.next().and_then(|v| v.parse().ok()).unwrap_or(f64::NAN),
            );
            println!(
                "  OpenCV {ver} cv2.inpaint: {:.1} ms  (ours / OpenCV = {:.2})",
                t * 1e3,
                ours / t
            );
        }
        _ => println!("  OpenCV timing skipped ({py} with cv2 not available; set UNSEEN_PYTHON)"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn morph() {
    let (w, h) = (256usize, 256usize);
    let f = 0.5 * w as f64 / (30f64).to_radians().tan();
    let a = Camera::new("a", w as u32, h as u32, f, f, DMat3::IDENTITY, DVec3::ZERO).unwrap();
    let b = Camera::new(
        "b",
        w as u32,
        h as u32,
        f,
        f,
        DMat3::from_rotation_y(10f64.to_radians()),
        DVec3::new(0.4, 0.0, 0.1),
    )
    .unwrap();
    let mut u = Uniform::new(4);
    let img = ImageF32::new(w, h, 3, (0..w * h * 3).map(|_| u.unit()).collect()).unwrap();
    let depth: Vec<f32> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
            4.0 + x - 1.5 * (((x * 5.0).fract() < 0.3) && (y * 3.0).fract() < 0.4) as i32 as f32
        })
        .collect();
    let ka = Keyframe {
        image: &img,
        camera: &a,
        depth: Some(&depth),
    };
    let kb = Keyframe {
        image: &img,
        camera: &b,
        depth: Some(&depth),
    };
    let n = 6;
    let (t, _) = best(3, || {
        Morph::default().generate(ka, kb, n).unwrap();
    });
    println!(
        "morph 256x256: {:.1} ms per intermediate frame ({} frames)",
        t * 1e3 / (n - 2) as f64,
        n
    );
}

fn tract_depth() {
    let Ok(card) = std::env::var("UNSEEN_DEPTH_CARD") else {
        println!("tract depth model: skipped (set UNSEEN_DEPTH_CARD=path/to/card.json)");
        return;
    };
    let d = unseen::models::onnx::OnnxDepth::load(std::path::Path::new(&card)).unwrap();
    let img = ImageF32::new(640, 480, 3, vec![0.5; 640 * 480 * 3]).unwrap();
    use unseen::models::DepthEstimator;
    d.estimate(&img, None).unwrap(); // plan built once
    let (t, _) = best(3, || {
        d.estimate(&img, None).unwrap();
    });
    let (mw, mh) = d.0.model_size(640, 480);
    println!(
        "tract depth model {card}: {:.0} ms per 640x480 image (model input {mw}x{mh})",
        t * 1e3
    );
}

fn main() {
    telea();
    morph();
    tract_depth();
}
