//! At the scale real captures have: `cargo bench --bench scale [-- --sizes 0.1,1,3,6]
//! [--width 1920] [--height 1080] [--modes render,oracle,train] [--json FILE] [--keep DIR]`.
//!
//! Seeded scenes (`scene::random_scene`, SH degree 3, σ 0.002–0.02 in a box 2–6 in front of
//! the camera: a 1080p view sees nearly every Gaussian, at σ ≈ 0.5–17 px) of each size in millions are
//! written as PLY files into a temporary folder, then every (mode, size) runs in a child
//! process of its own, so that its peak resident memory (`VmHWM`) is its own:
//!
//! | mode | what the child does (as the CLI does it) | memory against |
//! |---|---|---|
//! | `render` | `unseen render`: read the PLY (streamed), render RGB, write the PNG | the PLY's bytes |
//! | `oracle` | `unseen oracle`'s forward: read the PLY, render every output with the backward state, dump every array as `.npy` | the PLY's bytes (and the render's peak) |
//! | `train` | one training iteration (`Trainer::step_on`, INRIA's loss, Adam, no densification) on one view whose target is the scene's own render from a shifted camera, after one iteration that sized the buffers | the bytes of the parameters and Adam's two moments |
//!
//! Per row: seconds reading, computing and writing; the blend's Gaussian-pixel pairs and the
//! computing time per pair and per Gaussian (once the image saturates, pairs stop growing
//! with the scene and the per-Gaussian stages dominate); peak memory in MB and per
//! Gaussian, and its ratio to what the row is measured against. The first line names
//! the machine. Times are one run each: compare rows of one run, not runs of two machines.

mod common;

use std::path::{Path, PathBuf};
use std::time::Instant;
use unseen::camera::Camera;
use unseen::gaussian::ply;
use unseen::raster::{Outputs, RenderOptions, render};

/// The seeded scenes' σ range (world units) and seed.
const SCALE_LO: f32 = 0.002;
const SCALE_HI: f32 = 0.02;
const SEED: u64 = 7;

/// One child's measurement, printed by it as a JSON line.
#[derive(serde::Serialize, serde::Deserialize, Clone, Debug)]
struct Measure {
    mode: String,
    gaussians: usize,
    width: u32,
    height: u32,
    file_bytes: u64,
    read_seconds: f64,
    compute_seconds: f64,
    write_seconds: f64,
    pairs: u64,
    peak_bytes: u64,
    /// What the peak is measured against (the file's, or the parameters' and moments'
    /// bytes).
    reference_bytes: u64,
}

/// A folder removed when dropped (also on a panic).
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The camera the scenes are rendered from, and the shifted one a training target is.
fn camera(width: u32, height: u32, shifted: bool) -> Camera {
    use glam::DVec3;
    let eye = if shifted {
        DVec3::new(0.05, 0.0, 0.0)
    } else {
        DVec3::ZERO
    };
    Camera::look_at(
        "scale",
        width,
        height,
        60f64.to_radians(),
        eye,
        eye + DVec3::Z,
        DVec3::NEG_Y,
    )
    .expect("a valid camera")
}

fn peak() -> u64 {
    unseen::io::peak_memory_bytes().unwrap_or(0)
}

/// The child: one mode on one PLY.
fn child(mode: &str, ply_path: &Path, width: u32, height: u32, out: &Path) -> Measure {
    unseen::sys::keep_freed_memory(); // as the CLI does
    let file_bytes = std::fs::metadata(ply_path).unwrap().len();
    let t0 = Instant::now();
    let (scene, _) = ply::read_ply(ply_path).unwrap();
    let read_seconds = t0.elapsed().as_secs_f64();
    let cam = camera(width, height, false);
    let n = scene.len();
    let params_bytes = 4
        * (scene.means.len() * 3
            + scene.log_scales.len() * 3
            + scene.quats.len() * 4
            + scene.opacity_logits.len()
            + scene.sh_dc.len() * 3
            + scene.sh_rest.len()) as u64;
    let (compute_seconds, write_seconds, pairs, reference_bytes) = match mode {
        "render" => {
            let opts = RenderOptions {
                outputs: Outputs::RGB,
                ..RenderOptions::default()
            };
            let t = Instant::now();
            let mut r = render(&scene, &cam, &opts).unwrap();
            let compute = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let img = unseen::io::image::ImageF32::new(
                r.width,
                r.height,
                3,
                r.rgb.take().unwrap_or_default(),
            )
            .unwrap();
            unseen::io::image::write_png(&out.join("render.png"), &img).unwrap();
            (
                compute,
                t.elapsed().as_secs_f64(),
                r.report.pairs_evaluated,
                file_bytes,
            )
        }
        "oracle" => {
            let t = Instant::now();
            unseen::oracle::dump(&scene, &cam, &RenderOptions::default(), None, out).unwrap();
            (t.elapsed().as_secs_f64(), 0.0, 0, file_bytes)
        }
        "train" => {
            use unseen::train::trainer::{TrainConfig, Trainer};
            let target_cam = camera(width, height, true);
            let opts = RenderOptions {
                outputs: Outputs::RGB,
                ..RenderOptions::default()
            };
            let target = render(&scene, &target_cam, &opts).unwrap();
            let image = unseen::io::image::ImageF32::new(
                target.width,
                target.height,
                3,
                target.rgb.unwrap(),
            )
            .unwrap();
            let data = unseen::dataset::Dataset {
                root: out.to_path_buf(),
                layout: unseen::dataset::Layout::Unseen,
                views: vec![unseen::dataset::View {
                    camera: target_cam,
                    image,
                    depth: None,
                }],
                points: None,
                train: vec![0],
                test: vec![],
                heldout: vec![],
            };
            let config = TrainConfig {
                iterations: 10,
                densify: None,
                save_iterations: vec![],
                ..TrainConfig::default()
            };
            let mut t = Trainer::from_gaussians(&data, config, scene, 3).unwrap();
            t.step_on(0, None).unwrap();
            let clock = Instant::now();
            let p = t.step_on(0, None).unwrap();
            (
                clock.elapsed().as_secs_f64(),
                0.0,
                p.pairs,
                3 * params_bytes,
            )
        }
        other => panic!("unknown mode {other} (render, oracle, train)"),
    };
    Measure {
        mode: mode.into(),
        gaussians: n,
        width,
        height,
        file_bytes,
        read_seconds,
        compute_seconds,
        write_seconds,
        pairs,
        peak_bytes: peak(),
        reference_bytes,
    }
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    if let Some(i) = a.iter().position(|x| x == "--child") {
        let m = child(
            &a[i + 1],
            Path::new(&a[i + 2]),
            a[i + 3].parse().unwrap(),
            a[i + 4].parse().unwrap(),
            Path::new(&a[i + 5]),
        );
        println!("{}", serde_json::to_string(&m).unwrap());
        return;
    }
    let sizes: Vec<f64> = common::arg_text("--sizes")
        .unwrap_or_else(|| "0.1,1,3".into())
        .split(',')
        .map(|s| s.parse().expect("sizes in millions"))
        .collect();
    let width: u32 = common::arg_text("--width").map_or(1920, |v| v.parse().unwrap());
    let height: u32 = common::arg_text("--height").map_or(1080, |v| v.parse().unwrap());
    let modes: Vec<String> = common::arg_text("--modes")
        .unwrap_or_else(|| "render,oracle,train".into())
        .split(',')
        .map(String::from)
        .collect();
    println!("{}", common::machine());
    let dir = Scratch(std::env::temp_dir().join(format!("unseen-scale-{}", std::process::id())));
    std::fs::create_dir_all(&dir.0).unwrap();
    println!(
        "{:>7} {:>10} {:>9} {:>7} {:>9} {:>7} {:>9} {:>8} {:>8} {:>9} {:>8} {:>6}",
        "mode",
        "size",
        "gaussians",
        "read s",
        "compute s",
        "write s",
        "M pairs",
        "ns/pair",
        "ns/Gauss",
        "peak MB",
        "B/Gauss",
        "ratio"
    );
    let mut all = Vec::new();
    for &m in &sizes {
        let n = (m * 1e6).round() as usize;
        // `--keep DIR`: the scenes are written there and left (to profile a child on its
        // own: `scale --child MODE PLY WIDTH HEIGHT OUT`), and reused when present.
        let keep = common::arg_text("--keep").map(PathBuf::from);
        let ply_path = keep
            .as_deref()
            .unwrap_or(&dir.0)
            .join(format!("scene-{n}.ply"));
        if !ply_path.is_file() {
            let scene = unseen::scene::random_scene(n, 3, SEED, SCALE_LO, SCALE_HI);
            ply::write_ply(&scene, &ply_path).unwrap();
        }
        for mode in &modes {
            let out = dir.0.join(format!("{mode}-{n}"));
            std::fs::create_dir_all(&out).unwrap();
            let o = std::process::Command::new(std::env::current_exe().unwrap())
                .args(["--child", mode])
                .arg(&ply_path)
                .args([width.to_string(), height.to_string()])
                .arg(&out)
                .output()
                .unwrap();
            assert!(
                o.status.success(),
                "{mode} at {n}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            let text = String::from_utf8_lossy(&o.stdout);
            let line = text.lines().last().expect("the child's measure");
            let r: Measure = serde_json::from_str(line).unwrap();
            let _ = std::fs::remove_dir_all(&out);
            println!(
                "{:>7} {:>10} {:>9} {:>7.2} {:>9.3} {:>7.2} {:>9.1} {:>8.3} {:>8.1} {:>9.0} {:>8.0} {:>6.2}",
                r.mode,
                format!("{}x{}", r.width, r.height),
                r.gaussians,
                r.read_seconds,
                r.compute_seconds,
                r.write_seconds,
                r.pairs as f64 / 1e6,
                if r.pairs > 0 {
                    r.compute_seconds * 1e9 / r.pairs as f64
                } else {
                    f64::NAN
                },
                r.compute_seconds * 1e9 / r.gaussians as f64,
                r.peak_bytes as f64 / 1e6,
                r.peak_bytes as f64 / r.gaussians as f64,
                r.peak_bytes as f64 / r.reference_bytes as f64
            );
            all.push(r);
        }
        if keep.is_none() {
            let _ = std::fs::remove_file(&ply_path);
        }
    }
    if let Some(path) = common::arg_text("--json") {
        let text = serde_json::to_string_pretty(&all).unwrap();
        std::fs::write(&path, text).unwrap_or_else(|e| panic!("{path}: {e}"));
    }
}
