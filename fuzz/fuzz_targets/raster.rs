//! Arbitrary Gaussian parameters (any bit patterns, NaN and Inf included) and camera sizes:
//! the rasterizer never panics and never writes a non-finite value, and the AVX2 and scalar
//! kernels agree bit for bit.
#![no_main]
use libfuzzer_sys::fuzz_target;
use unseen::raster::{Kernel, Outputs, RenderOptions, render};
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let Some((cam, g, _)) = common::float_scene(data, 64) else { return };
    let opts = RenderOptions { outputs: Outputs::ALL, background: [0.1, 0.2, 0.3], ..Default::default() };
    let a = render(&g, &cam, &opts).unwrap();
    let b = render(&g, &cam, &RenderOptions { kernel: Kernel::Scalar, ..opts }).unwrap();
    assert_eq!(a, b);
    for v in [&a.rgb, &a.alpha, &a.depth, &a.expected_depth, &a.final_t].into_iter().flatten() {
        assert!(v.iter().all(|x| x.is_finite()));
    }
});
