//! Arbitrary Gaussian parameters (any bit patterns) and image gradients: the forward with
//! backward state and the backward never panic, and finite gradients come out of
//! parameters of moderate size (|x| ≤ 1e3; a finite SH coefficient of 1.7e38 overflows the
//! mean's gradient in f32, as the fuzzer showed — arithmetic, not a defect).
#![no_main]
use libfuzzer_sys::fuzz_target;
use unseen::camera::Camera;
use unseen::gaussian::Gaussians;
use unseen::raster::backward::{GradGroups, Gradients, ImageGrads, backward_into, render_for_backward};
use unseen::raster::{Outputs, RenderOptions};

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    let w = 1 + (data[0] as u32 % 32);
    let h = 1 + (data[1] as u32 % 32);
    let floats: Vec<f32> = data[4..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let mut g = Gaussians::new(1).unwrap();
    for p in floats.chunks_exact(23) {
        g.push([p[0], p[1], p[2]], [p[3], p[4], p[5]], [p[6], p[7], p[8], p[9]], p[10],
               [p[11], p[12], p[13]], &p[14..23]);
    }
    let moderate = floats.iter().all(|x| x.abs() <= 1e3);
    let opts = RenderOptions {
        outputs: Outputs { rgb: true, expected_depth: true, ..Outputs::default() },
        ..Default::default()
    };
    let cam = Camera::look_at("fuzz", w, h, 1.0, [0.1, 0.2, -0.3].into(), [0.0, 0.0, 3.0].into(),
                              [0.2, -1.0, 0.0].into()).unwrap();
    let Ok(fwd) = render_for_backward(&g, &cam, &opts) else { return };
    let n = (w * h) as usize;
    let seed = data[2] as f32 / 255.0 - 0.5;
    let v = ImageGrads {
        rgb: Some((0..3 * n).map(|i| seed * ((i % 7) as f32 - 3.0)).collect()),
        expected_depth: Some(vec![seed; n]),
        ..Default::default()
    };
    let mut grads = Gradients::default();
    let groups = GradGroups { background: false, ..GradGroups::ALL };
    if backward_into(&g, &cam, &opts, &fwd, &v, &groups, &mut grads).is_ok() && moderate {
        for p in unseen::gaussian::Param::ALL {
            assert!(grads.param(p).iter().all(|x| x.is_finite()), "{p:?}");
        }
    }
});
