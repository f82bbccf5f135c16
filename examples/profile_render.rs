//! One render of a seeded random scene, for profilers (callgrind, perf):
//! `cargo run --release --example profile_render -- N WIDTH HEIGHT`.
use unseen::raster::{RenderOptions, render};
use unseen::scene::{default_camera, random_scene};

fn main() {
    let a: Vec<usize> = std::env::args()
        .skip(1)
        .map(|s| s.parse().expect("numbers"))
        .collect();
    let (n, w, h) = (
        a.first().copied().unwrap_or(10_000),
        a.get(1).copied().unwrap_or(1024),
        a.get(2).copied().unwrap_or(768),
    );
    let scene = random_scene(n, 3, 7, 0.003, 0.03);
    let r = render(
        &scene,
        &default_camera(w as u32, h as u32),
        &RenderOptions::default(),
    )
    .unwrap();
    println!("{:?}", r.report);
}
