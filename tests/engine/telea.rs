//! Telea inpainting against OpenCV's `cv2.inpaint(..., INPAINT_TELEA)`
//! (`reference_data/opencv/telea/`, made by `make_telea_goldens.py`).

use crate::support::case_dirs;
use unseen::io::npy::read_npy_f32;
use unseen::models::telea::{inpaint, inpaint_traced};

#[derive(serde::Deserialize)]
struct Case {
    radius: f64,
    dtype: String,
    channels: usize,
    height: usize,
    width: usize,
}

fn read_u8_png(path: &std::path::Path) -> (usize, usize, usize, Vec<u8>) {
    let img = image::open(path).unwrap();
    let (w, h) = (img.width() as usize, img.height() as usize);
    if img.color().channel_count() == 1 {
        (w, h, 1, img.into_luma8().into_raw())
    } else {
        (w, h, 3, img.into_rgb8().into_raw())
    }
}

/// Every value of every case equals OpenCV's: 8-bit gray and RGB, float, radii 1–8,
/// scribbles, blobs and masks touching the border.
#[test]
fn telea_matches_opencv() {
    let mut total = (0usize, 0usize);
    for dir in case_dirs("opencv/telea") {
        let name = dir.file_name().unwrap().to_string_lossy().into_owned();
        let case: Case =
            serde_json::from_str(&std::fs::read_to_string(dir.join("case.json")).unwrap()).unwrap();
        let (mw, mh, _, m) = read_u8_png(&dir.join("mask.png"));
        assert_eq!((mw, mh), (case.width, case.height));
        let mask: Vec<bool> = m.iter().map(|&v| v != 0).collect();
        let (same, n, worst) = if case.dtype == "uint8" {
            let (w, h, c, img) = read_u8_png(&dir.join("input.png"));
            assert_eq!((w, h, c), (case.width, case.height, case.channels));
            let (_, _, _, want) = read_u8_png(&dir.join("expected.png"));
            let got = inpaint(&img, w, h, c, &mask, case.radius).unwrap();
            let same = got.iter().zip(&want).filter(|(a, b)| a == b).count();
            let worst = got
                .iter()
                .zip(&want)
                .map(|(&a, &b)| (a as i32 - b as i32).abs())
                .max()
                .unwrap();
            (same, got.len(), worst as f32)
        } else {
            let (shape, img) = read_npy_f32(&dir.join("input.npy")).unwrap();
            let (_, want) = read_npy_f32(&dir.join("expected.npy")).unwrap();
            let got = inpaint(&img, shape[1], shape[0], 1, &mask, case.radius).unwrap();
            let same = got
                .iter()
                .zip(&want)
                .filter(|(a, b)| a.to_bits() == b.to_bits())
                .count();
            let worst = got
                .iter()
                .zip(&want)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            (same, got.len(), worst)
        };
        println!(
            "{name:24} identical {same}/{n} ({:.3} %), worst {worst}",
            100.0 * same as f64 / n as f64
        );
        // The floor is 99.5 % identical and every pixel within 2 levels; we
        // reproduce OpenCV 5.0.0 bit for bit on every case, so any difference is a
        // regression.
        assert_eq!(
            same,
            n,
            "{name}: {} values differ, worst by {worst}",
            n - same
        );
        total.0 += same;
        total.1 += n;
    }
    assert!(total.1 > 200_000);
}

/// Any channel count: the channels of a 4-channel image are filled with the 3-channel
/// weights (the first three equal the 3-channel result bit for bit); degenerate inputs
/// are handled without panics; bad sizes are clear errors.
#[test]
fn telea_any_channel_count_and_edge_cases() {
    let (w, h) = (23usize, 17usize);
    let mut u = unseen::rng::Uniform::new(5);
    let rgba: Vec<u8> = (0..w * h * 4).map(|_| (u.unit() * 255.0) as u8).collect();
    let rgb: Vec<u8> = rgba.chunks(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
    let mask: Vec<bool> = (0..w * h)
        .map(|i| (i % w) > 5 && (i % w) < 12 && (i / w) < 9)
        .collect();
    let a = inpaint(&rgba, w, h, 4, &mask, 3.0).unwrap();
    let b = inpaint(&rgb, w, h, 3, &mask, 3.0).unwrap();
    for (p, q) in a.chunks(4).zip(b.chunks(3)) {
        assert_eq!(&p[..3], q);
    }
    // Unmasked pixels never change; an empty mask changes nothing; a full mask has no
    // band, so nothing can be filled (OpenCV returns the input).
    for (i, &m) in mask.iter().enumerate() {
        if !m {
            assert_eq!(&a[4 * i..4 * i + 4], &rgba[4 * i..4 * i + 4]);
        }
    }
    assert_eq!(
        inpaint(&rgb, w, h, 3, &vec![false; w * h], 3.0).unwrap(),
        rgb
    );
    assert_eq!(
        inpaint(&rgb, w, h, 3, &vec![true; w * h], 3.0).unwrap(),
        rgb
    );
    // One-pixel-wide images and radius extremes.
    let col: Vec<f32> = (0..9).map(|v| v as f32).collect();
    let m: Vec<bool> = (0..9).map(|i| i == 4).collect();
    let r = inpaint(&col, 1, 9, 1, &m, 0.2).unwrap();
    assert!(r[4].is_finite());
    assert!(inpaint(&col, 9, 1, 1, &m, 1e9).unwrap()[4].is_finite());
    assert!(inpaint(&col, 3, 3, 1, &m, f64::NAN).is_err());
    assert!(inpaint(&col, 4, 2, 1, &m, 3.0).is_err());
    assert!(inpaint(&col, 3, 3, 1, &m[1..], 3.0).is_err());
}

/// The traced inpainting a port is judged by: without `forced` it is the inpainting, bit
/// for bit, on every OpenCV case (8-bit and float); the fill order numbers exactly the
/// masked pixels; forced to OpenCV's own output it recomputes OpenCV's values, with few
/// set aside; forced to a port whose first fill value is wrong, that value is still
/// judged against ours while every later value is computed from the port's.
#[test]
fn traced_inpainting_is_the_inpainting_and_judges_each_value_on_the_ports_predecessors() {
    let mut aside = (0usize, 0usize);
    for dir in case_dirs("opencv/telea") {
        let case: Case =
            serde_json::from_str(&std::fs::read_to_string(dir.join("case.json")).unwrap()).unwrap();
        if case.dtype != "uint8" {
            continue;
        }
        let (_, _, _, m) = read_u8_png(&dir.join("mask.png"));
        let mask: Vec<bool> = m.iter().map(|&v| v != 0).collect();
        let (w, h, c, img) = read_u8_png(&dir.join("input.png"));
        let (_, _, _, cv) = read_u8_png(&dir.join("expected.png"));
        let plain = inpaint(&img, w, h, c, &mask, case.radius).unwrap();
        let t = inpaint_traced(&img, w, h, c, &mask, case.radius, None).unwrap();
        assert_eq!(t.image, plain, "{}", dir.display());
        let mut order: Vec<i32> = t.order.iter().copied().filter(|&o| o >= 0).collect();
        order.sort_unstable();
        let fill = mask.iter().filter(|&&m| m).count();
        // A full-frame fill has no band and fills nothing.
        assert!(order.is_empty() || order == (0..fill as i32).collect::<Vec<_>>());
        for (p, &m) in mask.iter().enumerate() {
            assert_eq!(m, t.order[p] >= 0 || order.is_empty(), "{}", dir.display());
            assert!(t.time[p].is_finite());
        }
        let f = inpaint_traced(&img, w, h, c, &mask, case.radius, Some(&cv)).unwrap();
        assert_eq!(f.image, cv, "{}", dir.display());
        for (k, &a) in f.aside.iter().enumerate() {
            if mask[k / c] {
                aside.0 += (a != 0) as usize;
                aside.1 += 1;
                let v = f.mean[k] + f.term[k];
                assert!(
                    f.bound[k] >= 0.0 && f.bound[k] < 0.5,
                    "{v} ± {}",
                    f.bound[k]
                );
            }
        }
        // A port whose first fill value is off by 9 levels.
        let Some(first) = t.order.iter().position(|&o| o == 0) else {
            continue;
        };
        let mut port = cv.clone();
        port[first * c] = port[first * c].wrapping_add(9);
        let g = inpaint_traced(&img, w, h, c, &mask, case.radius, Some(&port)).unwrap();
        assert_eq!(g.image[first * c], cv[first * c], "judged against ours");
        let moved = (0..w * h)
            .filter(|&p| t.order[p] > 0)
            .any(|p| g.image[p * c] != cv[p * c] || g.mean[p * c] != f.mean[p * c]);
        assert!(moved, "{}: later values see the port's", dir.display());
    }
    println!(
        "set aside: {} of {} fill values ({:.2} %)",
        aside.0,
        aside.1,
        100.0 * aside.0 as f64 / aside.1 as f64
    );
    // Measured: 3.1 % of the fill values set aside on these cases, most at radius 1 (one
    // known neighbour: the value lands on a rounding boundary).
    assert!(aside.1 > 10_000 && aside.0 * 20 < aside.1, "{aside:?}");
}
