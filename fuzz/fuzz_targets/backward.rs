//! Arbitrary Gaussian parameters (any bit patterns) and image gradients: the forward with
//! backward state and the backward never panic, and finite gradients come out of
//! parameters of moderate size (|x| ≤ 1e3; a finite SH coefficient of 1.7e38 overflows the
//! mean's gradient in f32, as the fuzzer showed — arithmetic, not a defect).
#![no_main]
use libfuzzer_sys::fuzz_target;
use unseen::raster::backward::{GradGroups, Gradients, ImageGrads, backward_into, render_for_backward};
use unseen::raster::{Outputs, RenderOptions};
#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let Some((cam, g, floats)) = common::float_scene(data, 32) else { return };
    let (w, h) = (cam.width, cam.height);
    let moderate = floats.iter().all(|x| x.abs() <= 1e3);
    let opts = RenderOptions {
        outputs: Outputs { rgb: true, expected_depth: true, ..Outputs::default() },
        ..Default::default()
    };
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
