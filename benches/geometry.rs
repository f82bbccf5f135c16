//! DIBR warp and RANSAC alignment timings: `cargo bench --bench geometry`.
//!
//! DIBR: a 1024×768 RGB image over a procedural depth (a slanted wall with boxes in front,
//! so there are disocclusions), warped to a camera moved 0.15 and turned 4°; nearest,
//! nearest + crack closing, bilinear; 1 and all threads; best of 5.
//! RANSAC: 32 frames of 256×256 with 30 % outliers (depth space), adaptive count and a
//! fixed 1000 iterations; 1 and all threads; best of 3.

mod common;

use common::{best, pools};
use glam::{DMat3, DVec3};
use unseen::camera::Camera;
use unseen::io::image::ImageF32;
use unseen::rng::Uniform;
use unseen::warp::align::{Frame, RansacConfig, Space, ransac};
use unseen::warp::dibr::{Footprint, WarpOptions, warp};

fn main() {
    let (w, h) = (1024usize, 768usize);
    let f = 0.5 * w as f64 / (35f64).to_radians().tan();
    let from = Camera::new("a", w as u32, h as u32, f, f, DMat3::IDENTITY, DVec3::ZERO).unwrap();
    let to = Camera::new(
        "b",
        w as u32,
        h as u32,
        f,
        f,
        DMat3::from_rotation_y(4f64.to_radians()),
        DVec3::new(0.15, -0.05, 0.0),
    )
    .unwrap();
    let mut u = Uniform::new(3);
    let img = ImageF32::new(w, h, 3, (0..w * h * 3).map(|_| u.unit()).collect()).unwrap();
    let depth: Vec<f32> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
            let wall = 4.0 + 1.5 * x;
            let boxes = ((x * 6.0).fract() < 0.4 && (y * 4.0).fract() < 0.5) as i32 as f32;
            wall - boxes * 2.0
        })
        .collect();
    println!("DIBR {w}x{h}:");
    for (name, opts) in [
        ("nearest", WarpOptions::default()),
        (
            "nearest + close_cracks 1",
            WarpOptions {
                close_cracks: 1,
                ..WarpOptions::default()
            },
        ),
        (
            "bilinear",
            WarpOptions {
                footprint: Footprint::Bilinear,
                ..WarpOptions::default()
            },
        ),
    ] {
        for (n, pool) in pools() {
            let (t, r) =
                pool.install(|| best(5, || warp(&img, &depth, &from, &to, &opts).unwrap()));
            println!(
                "  {name:26} {n} thread(s): {:7.2} ms  ({:.1} Mpixel/s, {} holes)",
                t * 1e3,
                (w * h) as f64 / t / 1e6,
                r.holes.iter().filter(|&&x| x).count()
            );
        }
    }
    let (fw, fh, frames) = (256usize, 256usize, 32usize);
    let mut data = Vec::new();
    for _ in 0..frames {
        let est: Vec<f32> = (0..fw * fh).map(|_| u.range(0.1, 1.0)).collect();
        let d: Vec<f32> = est
            .iter()
            .map(|&r| {
                if u.unit() < 0.3 {
                    u.range(0.5, 10.0)
                } else {
                    2.5 * r + 0.7 + 0.002 * u.normal()
                }
            })
            .collect();
        data.push((est, d));
    }
    let fr: Vec<Frame> = data
        .iter()
        .map(|(e, d)| Frame {
            estimate: e,
            depth: d,
        })
        .collect();
    println!(
        "RANSAC {frames} frames of {fw}x{fh} ({} pixels), 30 % outliers:",
        frames * fw * fh
    );
    for (name, cfg) in [
        ("adaptive (conf 0.999)", RansacConfig::default()),
        (
            "fixed 1000 iterations",
            RansacConfig {
                confidence: None,
                iterations: 1000,
                ..RansacConfig::default()
            },
        ),
    ] {
        for (n, pool) in pools() {
            let (t, a) = pool.install(|| best(3, || ransac(&fr, Space::Depth, &cfg).unwrap()));
            println!(
                "  {name:24} {n} thread(s): {:8.2} ms  (s {:.4}, t {:.4}, {} inliers)",
                t * 1e3,
                a.scale,
                a.offset,
                a.inliers
            );
        }
    }
}
