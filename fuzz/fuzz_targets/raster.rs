//! Arbitrary Gaussian parameters (any bit patterns, NaN and Inf included) and camera sizes:
//! the rasterizer never panics and never writes a non-finite value, and the AVX2 and scalar
//! kernels agree bit for bit.
#![no_main]
use libfuzzer_sys::fuzz_target;
use unseen::gaussian::Gaussians;
use unseen::raster::{Kernel, Outputs, RenderOptions, render};
use unseen::camera::Camera;

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    let w = 1 + (data[0] as u32 % 64);
    let h = 1 + (data[1] as u32 % 64);
    let floats: Vec<f32> =
        data[4..].chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    let mut g = Gaussians::new(1).unwrap();
    for p in floats.chunks_exact(23) {
        g.push([p[0], p[1], p[2]], [p[3], p[4], p[5]], [p[6], p[7], p[8], p[9]], p[10],
               [p[11], p[12], p[13]], &p[14..23]);
    }
    let opts = RenderOptions { outputs: Outputs::ALL, background: [0.1, 0.2, 0.3], ..Default::default() };
    // A rotated camera, so that huge means can overflow in camera space.
    let cam = Camera::look_at("fuzz", w, h, 1.0, [0.1, 0.2, -0.3].into(), [0.0, 0.0, 3.0].into(), [0.2, -1.0, 0.0].into()).unwrap();
    let a = render(&g, &cam, &opts).unwrap();
    let b = render(&g, &cam, &RenderOptions { kernel: Kernel::Scalar, ..opts }).unwrap();
    assert_eq!(a, b);
    for v in [&a.rgb, &a.alpha, &a.depth, &a.expected_depth, &a.final_t].into_iter().flatten() {
        assert!(v.iter().all(|x| x.is_finite()));
    }
});
