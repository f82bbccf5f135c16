//! Model slots: the classical defaults (`depth-fill`, `identity`, `bilateral`), the
//! registry by name, and the `morph` video generator against Mitsuba renders at the
//! interpolated poses (`reference_data/mitsuba/morph/`, `make_morph_goldens.py`).

use crate::support::{bits, reference, with_threads};
use unseen::camera::inria::read_cameras_json;
use unseen::io::image::{ImageF32, read_exr, read_png};
use unseen::models::morph::{Morph, interpolate_camera};
use unseen::models::{
    DepthHint, DepthKind, Keyframe, VideoGenerator, artifact_fixer, depth_estimator, inpainter,
    video_generator,
};

/// Floor of the PSNR of morph's intermediate frames against Mitsuba on the pixels an end
/// frame saw (measured 30.6–32.2 dB on lounge heldout_025 → heldout_033, n = 5, 0.2–0.8 %
/// invented): ~2 dB under the worst frame, for the same reasons as the DIBR floor (§18:
/// path-tracing noise, view-dependent shading, box-filtered pixels).
const MORPH_PSNR_FLOOR_DB: f64 = 28.5;

#[test]
fn morph_matches_mitsuba_at_interpolated_poses() {
    let root = reference("scenes/lounge");
    let cams = read_cameras_json(&root.join("cameras.json")).unwrap();
    let (na, nb) = ("heldout_025", "heldout_033");
    let cam = |n: &str| cams.iter().find(|c| c.name == n).unwrap().clone();
    let (ca, cb) = (cam(na), cam(nb));
    let img = |n: &str| read_png(&root.join(format!("images/{n}.png"))).unwrap();
    let dep = |n: &str| {
        read_exr(&root.join(format!("depth/{n}.exr")), &["Y"])
            .unwrap()
            .data
    };
    let (ia, ib, da, db) = (img(na), img(nb), dep(na), dep(nb));
    let start = Keyframe {
        image: &ia,
        camera: &ca,
        depth: Some(&da),
    };
    let end = Keyframe {
        image: &ib,
        camera: &cb,
        depth: Some(&db),
    };
    let generator = Morph::default();
    let v = generator.generate(start, end, 5).unwrap();
    assert_eq!(v.frames.len(), 5);
    assert_eq!(
        bits(&v.frames[0].data),
        bits(&ia.data),
        "first frame = start"
    );
    assert_eq!(bits(&v.frames[4].data), bits(&ib.data), "last frame = end");
    assert_eq!(v.cameras[0], ca);
    assert_eq!(v.cameras[4], cb);
    let golden = reference(&format!("mitsuba/morph/{na}__{nb}"));
    let gcams = read_cameras_json(&golden.join("cameras.json")).unwrap();
    for k in 1..4 {
        let c = &v.cameras[k];
        let g = &gcams[k - 1];
        assert!((c.center - g.center).length() < 1e-9, "frame {k} centre");
        let dr = (c.world_from_camera_rotation - g.world_from_camera_rotation).to_cols_array();
        assert!(dr.iter().all(|d| d.abs() < 1e-9), "frame {k} rotation");
        let want = read_png(&golden.join(format!("frame_{k}.png"))).unwrap();
        let inv = &v.invented.as_ref().unwrap()[k];
        let (mut se, mut n) = (0f64, 0usize);
        for (p, &i) in inv.iter().enumerate() {
            if !i {
                for ch in 0..3 {
                    let d = (v.frames[k].data[3 * p + ch] - want.data[3 * p + ch]) as f64;
                    se += d * d;
                }
                n += 3;
            }
        }
        let psnr = -10.0 * (se / n as f64).log10();
        let frac = inv.iter().filter(|&&b| b).count() as f64 / inv.len() as f64;
        println!(
            "frame {k}: PSNR {psnr:.2} dB on seen pixels, {:.1} % invented",
            100.0 * frac
        );
        assert!(psnr > MORPH_PSNR_FLOOR_DB, "frame {k}: {psnr:.2} dB");
        assert!(frac < 0.2);
        let d = &v.depths.as_ref().unwrap()[k];
        assert!(
            d.iter().all(|z| z.is_finite() && *z > 0.0),
            "frame {k} depth"
        );
    }
    // Deterministic across thread counts; errors are clear.
    let again = with_threads(2, || generator.generate(start, end, 5).unwrap());
    let one = with_threads(1, || generator.generate(start, end, 5).unwrap());
    assert_eq!(again, one);
    assert!(generator.generate(start, end, 1).is_err());
    let nodepth = Keyframe { depth: None, ..end };
    assert!(
        generator
            .generate(start, nodepth, 5)
            .unwrap_err()
            .to_string()
            .contains("depth")
    );
    let mut small = ca.clone();
    small.width = 80;
    assert!(interpolate_camera(&ca, &small, 0.5, "x".into()).is_err());
}

#[test]
fn classical_slots_and_registry() {
    // depth-fill: known depth unchanged, holes filled between the known values.
    let (w, h) = (24usize, 18usize);
    let depth: Vec<f32> = (0..w * h).map(|i| 2.0 + 0.05 * (i % w) as f32).collect();
    let mut hint = depth.clone();
    let mask: Vec<bool> = (0..w * h)
        .map(|i| (8..14).contains(&(i % w)) && (5..12).contains(&(i / w)))
        .collect();
    hint[0] = f32::NAN;
    hint[1] = -1.0;
    let img = ImageF32::new(w, h, 3, vec![0.5; w * h * 3]).unwrap();
    let est = depth_estimator(&"depth-fill".parse().unwrap()).unwrap();
    let d = est
        .estimate(
            &img,
            Some(DepthHint {
                depth: &hint,
                mask: Some(&mask),
            }),
        )
        .unwrap();
    assert_eq!(d.kind, DepthKind::Depth);
    for p in 2..w * h {
        if mask[p] {
            assert!(
                d.values[p] > 2.3 && d.values[p] < 2.8,
                "{p}: {}",
                d.values[p]
            );
        } else {
            assert_eq!(d.values[p], depth[p]);
        }
    }
    assert!(d.values[0].is_finite() && d.values[1] > 0.0);
    assert!(
        est.estimate(&img, None)
            .unwrap_err()
            .to_string()
            .contains("hint")
    );
    // Inpainting by name: telea fills only the mask.
    let mut u = unseen::rng::Uniform::new(3);
    let rgb = ImageF32::new(w, h, 3, (0..w * h * 3).map(|_| u.unit()).collect()).unwrap();
    let t = inpainter(&"telea".parse().unwrap())
        .unwrap()
        .inpaint(&rgb, &mask)
        .unwrap();
    for (p, &m) in mask.iter().enumerate() {
        if !m {
            assert_eq!(&t.data[3 * p..3 * p + 3], &rgb.data[3 * p..3 * p + 3]);
        }
    }
    // Fixers: identity is exact; bilateral keeps a flat image and a strong edge.
    assert_eq!(
        artifact_fixer(&"identity".parse().unwrap())
            .unwrap()
            .fix(&rgb, None)
            .unwrap(),
        rgb
    );
    let step: Vec<f32> = (0..w * h)
        .map(|i| if i % w < 12 { 0.1 } else { 0.9 })
        .collect();
    let s = ImageF32::new(w, h, 1, step.clone()).unwrap();
    let b = artifact_fixer(&"bilateral".parse().unwrap())
        .unwrap()
        .fix(&s, None)
        .unwrap();
    for (x, y) in b.data.iter().zip(&step) {
        assert!((x - y).abs() < 1e-5, "edge kept: {x} vs {y}");
    }
    let noisy = ImageF32::new(
        w,
        h,
        3,
        rgb.data.iter().map(|v| 0.5 + 0.02 * (v - 0.5)).collect(),
    )
    .unwrap();
    let sm = artifact_fixer(&"bilateral".parse().unwrap())
        .unwrap()
        .fix(&noisy, None)
        .unwrap();
    let var = |v: &[f32]| v.iter().map(|x| (x - 0.5) * (x - 0.5)).sum::<f32>();
    assert!(
        var(&sm.data) < 0.5 * var(&noisy.data),
        "small noise is smoothed"
    );
    // Unknown names are clear errors.
    for e in [
        "lama".parse::<unseen::models::InpaintModel>().unwrap_err(),
        "midas".parse::<unseen::models::DepthModel>().unwrap_err(),
        "difix".parse::<unseen::models::FixerModel>().unwrap_err(),
        "dynamicrafter"
            .parse::<unseen::models::VideoModel>()
            .unwrap_err(),
    ] {
        assert!(e.to_string().contains("unknown"), "{e}");
    }
    assert!(video_generator(&"morph".parse().unwrap()).is_ok());
    // Video depth: per frame, the same maps as the image estimator.
    let vd = unseen::models::video_depth_estimator(&"depth-fill".parse().unwrap()).unwrap();
    let h1 = DepthHint {
        depth: &hint,
        mask: Some(&mask),
    };
    let maps = vd
        .estimate(&[img.clone(), img.clone()], Some(&[h1, h1]))
        .unwrap();
    assert_eq!(maps.len(), 2);
    assert_eq!(maps[1], d);
    assert!(
        vd.estimate(std::slice::from_ref(&img), Some(&[h1, h1]))
            .is_err()
    );
}

/// A clip that cannot be made (end frames of different sizes) is an error of kind
/// `Degenerate`, which the pipeline records and goes on from (`cannot_make_clip`, decided by
/// the kind, never the text); a malformed request (fewer than two frames) is `Invalid`
/// and stops the run.
#[test]
fn morph_says_by_kind_which_clips_cannot_be_made() {
    use unseen::error::ErrorKind;
    use unseen::models::morph::cannot_make_clip;
    let root = reference("scenes/lounge");
    let cams = read_cameras_json(&root.join("cameras.json")).unwrap();
    let (ca, cb) = (&cams[0], &cams[1]);
    let ia = read_png(&root.join(format!("images/{}.png", ca.name))).unwrap();
    let ib = ImageF32::new(
        ia.width - 1,
        ia.height,
        3,
        vec![0.5; (ia.width - 1) * ia.height * 3],
    )
    .unwrap();
    let (da, db) = (
        vec![2.0; ia.width * ia.height],
        vec![2.0; ib.width * ib.height],
    );
    let key = |image, camera, depth| Keyframe {
        image,
        camera,
        depth: Some(depth),
    };
    let e = Morph::default()
        .generate(key(&ia, ca, &da), key(&ib, cb, &db), 3)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::Degenerate, "{e}");
    assert!(cannot_make_clip(&e));
    let e = Morph::default()
        .generate(key(&ia, ca, &da), key(&ia, cb, &da), 1)
        .unwrap_err();
    assert_eq!(e.kind, ErrorKind::Invalid, "{e}");
    assert!(!cannot_make_clip(&e));
}
