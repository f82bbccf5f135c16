//! DIBR forward warp against Mitsuba: warping a view to a nearby view reproduces Mitsuba's
//! render on the pixels visible from both, and its holes are the true disocclusions
//! (ground truth by Mitsuba ray tests, `reference_data/mitsuba/dibr/`); plus exact
//! properties on constructed cases.

use crate::support::{bits, case_dirs, reference, with_threads};
use unseen::camera::Camera;
use unseen::camera::inria::read_cameras_json;
use unseen::io::image::{ImageF32, read_exr, read_png};
use unseen::warp::dibr::{Footprint, WarpOptions, Warped, warp, warp_traced};

struct Pair {
    name: String,
    a: Camera,
    b: Camera,
    image_a: ImageF32,
    depth_a: Vec<f32>,
    image_b: ImageF32,
    visible: Vec<bool>,
}

fn pairs() -> Vec<Pair> {
    let mut out = Vec::new();
    for scene_dir in case_dirs("mitsuba/dibr") {
        let scene = scene_dir.file_name().unwrap().to_str().unwrap().to_string();
        let root = reference(&format!("scenes/{scene}"));
        let cams = read_cameras_json(&root.join("cameras.json")).unwrap();
        for case in case_dirs(&format!("mitsuba/dibr/{scene}")) {
            let n = case.file_name().unwrap().to_str().unwrap().to_string();
            let (a, b) = n.split_once("__").unwrap();
            let cam = |s: &str| cams.iter().find(|c| c.name == s).unwrap().clone();
            let vis = read_png(&case.join("visible.png")).unwrap();
            out.push(Pair {
                name: format!("{scene}/{n}"),
                a: cam(a),
                b: cam(b),
                image_a: read_png(&root.join(format!("images/{a}.png"))).unwrap(),
                depth_a: read_exr(&root.join(format!("depth/{a}.exr")), &["Y"])
                    .unwrap()
                    .data,
                image_b: read_png(&root.join(format!("images/{b}.png"))).unwrap(),
                visible: vis
                    .data
                    .iter()
                    .step_by(vis.channels)
                    .map(|&v| v > 0.5)
                    .collect(),
            });
        }
    }
    assert!(out.len() >= 4, "DIBR goldens missing");
    out
}

/// PSNR of the warp against the target render on pixels visible from both and covered,
/// and IoU of the holes with the true disocclusions.
fn score(p: &Pair, w: &Warped) -> (f64, f64) {
    let (mut se, mut n) = (0f64, 0usize);
    let (mut inter, mut union) = (0usize, 0usize);
    for (t, (&hole, &vis)) in w.holes.iter().zip(&p.visible).enumerate() {
        if !hole && vis {
            for c in 0..3 {
                let d = (w.image.data[3 * t + c] - p.image_b.data[3 * t + c]) as f64;
                se += d * d;
            }
            n += 3;
        }
        inter += (hole && !vis) as usize;
        union += (hole || !vis) as usize;
    }
    let psnr = -10.0 * (se / n as f64).log10();
    (psnr, inter as f64 / union.max(1) as f64)
}

/// Floors (measured on the 4 Mitsuba pairs, 160×120, 2026-11): co-visible PSNR 28.7–34.2
/// dB over all footprints; hole IoU 0.80–0.97 for nearest with crack closing and
/// 0.79–0.94 for bilinear. The floors sit ~1.5 dB / 0.05 below the worst pair: the renders
/// are path traced (256 spp noise, view-dependent highlights, box-filtered pixels against
/// pixel-centre depth), so a correct warp does not reach bit equality.
const PSNR_FLOOR_DB: f64 = 27.0;
const HOLE_IOU_FLOOR: f64 = 0.75;

#[test]
fn dibr_matches_mitsuba_on_covisible_pixels_and_finds_disocclusions() {
    for p in pairs() {
        for (label, opts, iou_floor) in [
            ("nearest", WarpOptions::default(), None),
            (
                "nearest+cracks",
                WarpOptions {
                    close_cracks: 1,
                    ..WarpOptions::default()
                },
                Some(HOLE_IOU_FLOOR),
            ),
            (
                "bilinear",
                WarpOptions {
                    footprint: Footprint::Bilinear,
                    ..WarpOptions::default()
                },
                Some(HOLE_IOU_FLOOR),
            ),
        ] {
            let w = warp(&p.image_a, &p.depth_a, &p.a, &p.b, &opts).unwrap();
            let (psnr, iou) = score(&p, &w);
            println!(
                "{:40} {label:16} psnr {psnr:6.2} dB  hole IoU {iou:.3}",
                p.name
            );
            assert!(
                psnr > PSNR_FLOOR_DB,
                "{} {label}: PSNR {psnr:.2} dB",
                p.name
            );
            // Nearest without cleaning leaves the cracks of magnified surfaces as holes:
            // its IoU is not a disocclusion detector and is only reported.
            if let Some(floor) = iou_floor {
                assert!(iou > floor, "{} {label}: hole IoU {iou:.3}", p.name);
            }
            assert_eq!(w.stats.invalid_depth, 0);
        }
    }
}

/// The same bits on 1 and 2 threads, for both footprints and with cleaning.
#[test]
fn dibr_is_deterministic_across_thread_counts() {
    let p = &pairs()[0];
    for footprint in [Footprint::Nearest, Footprint::Bilinear] {
        let opts = WarpOptions {
            footprint,
            close_cracks: 1,
            grow_holes: 2,
            ..WarpOptions::default()
        };
        let run = |t| {
            with_threads(t, || {
                warp(&p.image_a, &p.depth_a, &p.a, &p.b, &opts).unwrap()
            })
        };
        let (a, b) = (run(1), run(2));
        assert_eq!(bits(&a.image.data), bits(&b.image.data));
        assert_eq!(bits(&a.depth), bits(&b.depth));
        assert_eq!(a.holes, b.holes);
        assert_eq!(a.stats, b.stats);
    }
}

fn plane_camera(name: &str, w: u32, h: u32, f: f64) -> Camera {
    Camera::new(name, w, h, f, f, glam::DMat3::IDENTITY, glam::DVec3::ZERO).unwrap()
}

/// Exact cases: identity warp, z ties to the lower source index, invalid depths counted,
/// points behind or outside the target counted, hole growing, bad sizes refused.
#[test]
fn dibr_exact_cases() {
    let (w, h) = (8usize, 6usize);
    let img = ImageF32::new(w, h, 2, (0..w * h * 2).map(|v| v as f32).collect()).unwrap();
    let cam = plane_camera("a", w as u32, h as u32, 7.0);
    let depth = vec![2.5f32; w * h];
    for footprint in [Footprint::Nearest, Footprint::Bilinear] {
        let opts = WarpOptions {
            footprint,
            ..WarpOptions::default()
        };
        let id = warp(&img, &depth, &cam, &cam, &opts).unwrap();
        assert_eq!(id.image, img, "{footprint:?}: identity warp");
        assert_eq!(id.depth, depth);
        assert!(id.holes.iter().all(|&h| !h));
    }
    // Half resolution, same pose: source (2j, 2k), (2j+1, 2k), ... land in target (j, k)
    // at the same z; the lowest source index, (2j, 2k), wins.
    let half = plane_camera("b", (w / 2) as u32, (h / 2) as u32, 3.5);
    let r = warp(&img, &depth, &cam, &half, &WarpOptions::default()).unwrap();
    for k in 0..h / 2 {
        for j in 0..w / 2 {
            let s = 2 * k * w + 2 * j;
            assert_eq!(r.image.data[2 * (k * w / 2 + j)], img.data[2 * s]);
        }
    }
    // Invalid depths are skipped and counted, and leave holes.
    let mut bad = depth.clone();
    bad[3] = 0.0;
    bad[10] = f32::NAN;
    bad[11] = f32::INFINITY;
    bad[20] = -1.0;
    let r = warp(&img, &bad, &cam, &cam, &WarpOptions::default()).unwrap();
    assert_eq!(r.stats.invalid_depth, 4);
    assert_eq!(r.stats.raw_holes, 4);
    assert!(r.holes[3] && r.holes[10] && r.holes[11] && r.holes[20]);
    assert_eq!((r.image.data[6], r.depth[3]), (0.0, 0.0));
    // Crack closing fills an isolated hole from its neighbours (equal depth: their mean).
    let c = warp(
        &img,
        &bad,
        &cam,
        &cam,
        &WarpOptions {
            close_cracks: 1,
            ..WarpOptions::default()
        },
    )
    .unwrap();
    assert_eq!(c.stats.cracks_filled, 4);
    assert!(c.holes.iter().all(|&h| !h));
    assert_eq!(c.depth[3], 2.5);
    // Growing: one hole pixel at (3, 0) grows to a 3×2 block at the top border.
    let mut one = depth.clone();
    one[3] = 0.0;
    let g = warp(
        &img,
        &one,
        &cam,
        &cam,
        &WarpOptions {
            grow_holes: 1,
            ..WarpOptions::default()
        },
    )
    .unwrap();
    assert_eq!(g.holes.iter().filter(|&&h| h).count(), 6);
    assert_eq!(g.stats.grown, 5);
    // A target camera turned around sees everything behind it; one moved aside sees part.
    let back = Camera::new(
        "back",
        w as u32,
        h as u32,
        7.0,
        7.0,
        glam::DMat3::from_diagonal(glam::DVec3::new(-1.0, 1.0, -1.0)),
        glam::DVec3::ZERO,
    )
    .unwrap();
    let r = warp(&img, &depth, &cam, &back, &WarpOptions::default()).unwrap();
    assert_eq!(r.stats.behind_target, w * h);
    assert!(r.holes.iter().all(|&h| h));
    let aside = Camera::new(
        "aside",
        w as u32,
        h as u32,
        7.0,
        7.0,
        glam::DMat3::IDENTITY,
        glam::DVec3::new(1.0, 0.0, 0.0),
    )
    .unwrap();
    let r = warp(&img, &depth, &cam, &aside, &WarpOptions::default()).unwrap();
    assert!(r.stats.outside_target > 0 && r.stats.outside_target < w * h);
    // Wrong sizes are refused with a message naming the camera.
    let e = warp(&img, &depth[1..], &cam, &cam, &WarpOptions::default()).unwrap_err();
    assert!(e.to_string().contains("camera 'a'"), "{e}");
    let e = warp(&img, &depth, &half, &cam, &WarpOptions::default()).unwrap_err();
    assert!(e.to_string().contains("camera 'b'"), "{e}");
}

/// The traced warp a port is judged by: on every Mitsuba pair, both footprints, with and
/// without cleaning, it is the warp bit for bit on 1 and 2 threads; each source pixel's
/// projection is NaN exactly where its depth is invalid or behind the target; and few
/// target pixels lie near a decision.
#[test]
fn traced_warp_is_the_warp_and_sets_few_pixels_aside() {
    for p in pairs() {
        for (footprint, clean) in [
            (Footprint::Nearest, 0),
            (Footprint::Bilinear, 0),
            (Footprint::Bilinear, 1),
        ] {
            let opts = WarpOptions {
                footprint,
                close_cracks: clean,
                grow_holes: clean,
                ..WarpOptions::default()
            };
            let plain = warp(&p.image_a, &p.depth_a, &p.a, &p.b, &opts).unwrap();
            let run = |t| {
                with_threads(t, || {
                    warp_traced(&p.image_a, &p.depth_a, &p.a, &p.b, &opts).unwrap()
                })
            };
            let (t1, t2) = (run(1), run(2));
            assert_eq!(t1.warped, plain, "{}", p.name);
            assert_eq!(t1.aside, t2.aside);
            assert_eq!(bits(&t1.z), bits(&t2.z));
            let projected = t1.u.iter().filter(|u| !u.is_nan()).count();
            let s = plain.stats;
            assert_eq!(
                projected,
                p.depth_a.len() - s.invalid_depth - s.behind_target,
                "{}",
                p.name
            );
            let aside = t1.aside.iter().filter(|&&a| a != 0).count();
            let share = aside as f64 / t1.aside.len() as f64;
            println!(
                "{} {footprint:?} clean {clean}: {:.2} % set aside",
                p.name,
                100.0 * share
            );
            // Measured: 0.9–4.4 % on these pairs (most with bilinear and cleaning).
            assert!(share < 0.08, "{}: {share}", p.name);
        }
    }
}
