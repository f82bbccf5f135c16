//! Depth alignment: exact recovery, noise, outliers under RANSAC, reproducibility, errors.

use unseen::scene::Uniform;
use unseen::warp::align::{Frame, RansacConfig, Space, least_squares, ransac};

/// Relative estimates `r` and metric depths `d = s·r + t` (depth space) for `n` pixels.
fn synthetic(n: usize, s: f64, t: f64, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut u = Uniform::new(seed);
    let r: Vec<f32> = (0..n).map(|_| u.range(0.5, 4.0)).collect();
    let d = r.iter().map(|&x| (s * x as f64 + t) as f32).collect();
    (r, d)
}

#[test]
fn least_squares_recovers_scale_and_offset() {
    // Exact on noiseless data (to f32 rounding of the inputs).
    let (r, d) = synthetic(5000, 1.7, 0.3, 1);
    let a = least_squares(
        &[Frame {
            estimate: &r,
            depth: &d,
        }],
        Space::Depth,
    )
    .unwrap();
    assert!(
        (a.scale - 1.7).abs() < 1e-6 && (a.offset - 0.3).abs() < 1e-6,
        "{a:?}"
    );
    assert_eq!((a.inliers, a.valid), (5000, 5000));
    // Disparity space: 1/d = s·r + t.
    let disp: Vec<f32> = r
        .iter()
        .map(|&x| (1.0 / (0.5 * x as f64 + 0.1)) as f32)
        .collect();
    let a = least_squares(
        &[Frame {
            estimate: &r,
            depth: &disp,
        }],
        Space::Disparity,
    )
    .unwrap();
    assert!(
        (a.scale - 0.5).abs() < 1e-6 && (a.offset - 0.1).abs() < 1e-6,
        "{a:?}"
    );
    // Gaussian noise σ = 0.01 on 20 000 pixels: the estimate is within a few standard errors.
    let mut u = Uniform::new(2);
    let (r, d) = synthetic(20_000, 2.0, -0.5, 3);
    let noisy: Vec<f32> = d.iter().map(|&v| v + 0.01 * u.normal()).collect();
    let a = least_squares(
        &[Frame {
            estimate: &r,
            depth: &noisy,
        }],
        Space::Depth,
    )
    .unwrap();
    assert!(
        (a.scale - 2.0).abs() < 1e-3 && (a.offset + 0.5).abs() < 3e-3,
        "{a:?}"
    );
    // Invalid targets (0, NaN, Inf) and non-finite estimates are skipped.
    let mut d2 = d.clone();
    let mut r2 = r.clone();
    d2[0] = 0.0;
    d2[1] = f32::NAN;
    d2[2] = f32::INFINITY;
    r2[3] = f32::NAN;
    let a = least_squares(
        &[Frame {
            estimate: &r2,
            depth: &d2,
        }],
        Space::Depth,
    )
    .unwrap();
    assert_eq!(a.valid, 20_000 - 4);
}

#[test]
fn ransac_survives_forty_percent_outliers_and_is_reproducible() {
    let (r, mut d) = synthetic(4000, 0.8, 1.2, 4);
    let mut u = Uniform::new(5);
    for v in d.iter_mut().take(1600) {
        *v = u.range(0.1, 10.0); // 40 % outliers
    }
    // Two frames, as the multi-frame video alignment pools them.
    let frames = [
        Frame {
            estimate: &r[..2000],
            depth: &d[..2000],
        },
        Frame {
            estimate: &r[2000..],
            depth: &d[2000..],
        },
    ];
    let cfg = RansacConfig::default();
    let a = ransac(&frames, Space::Depth, &cfg).unwrap();
    // With the default 5 % band, ~2 % of the uniform outliers fall inside it and enter the
    // refit: within 1e-3. With a 1e-4 band none do: exact to f32 input rounding.
    assert!(
        (a.scale - 0.8).abs() < 1e-3 && (a.offset - 1.2).abs() < 1e-3,
        "{a:?}"
    );
    assert!(a.inliers >= 2400 && a.inliers < 2400 + 100, "{a:?}");
    let tight = RansacConfig {
        threshold: 1e-4,
        ..RansacConfig::default()
    };
    let b = ransac(&frames, Space::Depth, &tight).unwrap();
    assert!(
        (b.scale - 0.8).abs() < 1e-6 && (b.offset - 1.2).abs() < 1e-6,
        "{b:?}"
    );
    let plain = least_squares(&frames, Space::Depth).unwrap();
    assert!(
        (plain.scale - 0.8).abs() > 0.05,
        "least squares alone is pulled off: {plain:?}"
    );
    assert_eq!(
        ransac(&frames, Space::Depth, &cfg).unwrap(),
        a,
        "same seed, same answer"
    );
    let fixed = RansacConfig {
        confidence: None,
        iterations: 50,
        ..cfg
    };
    assert_eq!(
        ransac(&frames, Space::Depth, &fixed).unwrap(),
        ransac(&frames, Space::Depth, &fixed).unwrap()
    );
}

#[test]
fn degenerate_alignment_input_is_a_clear_error() {
    let one = least_squares(
        &[Frame {
            estimate: &[1.0],
            depth: &[2.0],
        }],
        Space::Depth,
    )
    .unwrap_err();
    assert!(one.to_string().contains("at least 2 valid pixels"), "{one}");
    let flat = [1.5f32; 10];
    let d: Vec<f32> = (0..10).map(|i| 1.0 + i as f32).collect();
    let e = least_squares(
        &[Frame {
            estimate: &flat,
            depth: &d,
        }],
        Space::Depth,
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("all estimated values are equal"),
        "{e}"
    );
    let e = ransac(
        &[Frame {
            estimate: &flat,
            depth: &d,
        }],
        Space::Depth,
        &RansacConfig::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("equal"), "{e}");
    let e = least_squares(
        &[Frame {
            estimate: &flat[..3],
            depth: &d,
        }],
        Space::Depth,
    )
    .unwrap_err();
    assert!(e.to_string().contains("3 estimates but 10 depths"), "{e}");
    let zeros = [0.0f32; 10];
    let e = least_squares(
        &[Frame {
            estimate: &d,
            depth: &zeros,
        }],
        Space::Depth,
    )
    .unwrap_err();
    assert!(e.to_string().contains("got 0"), "{e}");
}
