//! Cross-check against Mitsuba 3's ray-traced Gaussians (`ellipsoids` + `volprim_rf_basic`,
//! `reference_data/generate/make_mitsuba_crosscheck.py`). Not a bit-exact golden: ray
//! tracing takes each Gaussian's peak density along the pixel ray, splatting evaluates the
//! affine-projected 2D Gaussian with a 0.3 px² dilation at the pixel centre, Mitsuba keeps
//! densities down to its extent-4 shell while we drop α < 1/255, and it colours by the ray
//! direction instead of the direction to the mean. On small Gaussians near the axis these
//! differ by a few 1e-3 at the splat edges (tolerances below).
use crate::support::case_dirs;
use unseen::camera::inria::read_cameras_json;
use unseen::gaussian::ply::read_ply;
use unseen::io::image::read_exr;
use unseen::raster::{RenderOptions, render};

/// 99th percentile of the per-pixel largest channel difference: the α cut-off (Mitsuba
/// keeps densities down to its extent-4 shell, we stop at 1/255), the 0.3 px² dilation and the
/// affine projection, all at splat edges. Measured 6.6e-3 on both cases.
const MITSUBA_P99_ABS: f64 = 0.01;
/// Mean absolute difference over all pixels and channels (measured 7.1e-4 and 6.8e-4).
const MITSUBA_MEAN_ABS: f64 = 1e-3;
/// Pixels differing by more than 0.02 must be rare (measured 0.38%) and all brighter in
/// Mitsuba: `volprim_rf_basic` re-spawns rays 1e-4 past each shell hit and sporadically
/// counts a Gaussian twice (entry and back shell), which adds its contribution again.
const MITSUBA_OUTLIER_ABS: f64 = 0.02;
const MITSUBA_OUTLIER_FRACTION: f64 = 0.005;

#[test]
fn mitsuba_ellipsoids_crosscheck() {
    let cases = case_dirs("mitsuba/ellipsoids");
    assert!(cases.len() >= 2);
    for dir in cases {
        let (scene, _) = read_ply(&dir.join("scene.ply")).unwrap();
        let cam = &read_cameras_json(&dir.join("cameras.json")).unwrap()[0];
        let r = render(&scene, cam, &RenderOptions::default()).unwrap();
        let want = read_exr(&dir.join("rgb.exr"), &["R", "G", "B"])
            .unwrap()
            .data;
        let got = r.rgb.unwrap();
        let mut per_pixel = Vec::with_capacity(got.len() / 3);
        let (mut sum, mut outliers) = (0f64, 0usize);
        for (g, w) in got.chunks_exact(3).zip(want.chunks_exact(3)) {
            let d: Vec<f64> = (0..3).map(|k| (g[k] as f64 - w[k] as f64).abs()).collect();
            sum += d.iter().sum::<f64>();
            let m = d.iter().cloned().fold(0.0, f64::max);
            if m > MITSUBA_OUTLIER_ABS {
                outliers += 1;
                let brighter = w.iter().sum::<f32>() > g.iter().sum::<f32>();
                assert!(
                    brighter,
                    "{}: an outlier where Mitsuba is darker",
                    dir.display()
                );
            }
            per_pixel.push(m);
        }
        per_pixel.sort_by(f64::total_cmp);
        let p99 = per_pixel[(per_pixel.len() * 99) / 100];
        let mean = sum / got.len() as f64;
        let frac = outliers as f64 / per_pixel.len() as f64;
        let signal = want.iter().map(|&v| v as f64).sum::<f64>() / want.len() as f64;
        println!(
            "{}: p99 {p99:.3e}, mean {mean:.3e}, outliers {:.2}%, mean value {signal:.3e}",
            dir.display(),
            frac * 100.0
        );
        assert!(signal > 0.01, "the reference image is nearly empty");
        assert!(p99 <= MITSUBA_P99_ABS, "{}: p99 {p99}", dir.display());
        assert!(mean <= MITSUBA_MEAN_ABS, "{}: mean {mean}", dir.display());
        assert!(
            frac <= MITSUBA_OUTLIER_FRACTION,
            "{}: outliers {frac}",
            dir.display()
        );
    }
}
