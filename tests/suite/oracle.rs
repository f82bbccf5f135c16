//! `unseen oracle`: the dumped arrays load, hash as the manifest says, and agree with the
//! library's own render and gradients.
use crate::support::reference;
use sha2::{Digest, Sha256};
use std::process::Command;
use unseen::io::npy::read_npy_f32;

#[test]
fn oracle_backward_dump_is_complete_and_consistent() {
    let demo = reference("demo");
    let out = crate::support::TempDir::path_only("oracle");
    // A target: the render of another camera, written by `unseen render`.
    let tdir = out.join("target");
    let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .args([
            "render",
            demo.join("scene.ply").to_str().unwrap(),
            "--cameras",
        ])
        .arg(demo.join("cameras.json"))
        .args(["--camera", "view_05", "--out"])
        .arg(&tdir)
        .output()
        .unwrap();
    assert!(st.status.success());
    let o = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .args(["oracle", "backward", "--scene"])
        .arg(demo.join("scene.ply"))
        .arg("--cameras")
        .arg(demo.join("cameras.json"))
        .args(["--camera", "view_04", "--target"])
        .arg(tdir.join("view_05.png"))
        .arg("--out")
        .arg(out.join("dump"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dump = out.join("dump");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dump.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["conventions_version"], 1);
    let names: Vec<&str> = manifest["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    for want in [
        "means2d",
        "conics",
        "depths",
        "radii",
        "tile_offsets",
        "tile_ids",
        "final_t",
        "n_contrib",
        "rgb",
        "loss",
        "grad_means",
        "grad_log_scales",
        "grad_quats",
        "grad_opacity_logits",
        "grad_sh_dc",
        "grad_sh_rest",
    ] {
        assert!(names.contains(&want), "missing {want}");
    }
    for a in manifest["files"].as_array().unwrap() {
        let bytes = std::fs::read(dump.join(a["path"].as_str().unwrap())).unwrap();
        let hex: String = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(hex, a["sha256"].as_str().unwrap());
    }
    let (shape, rgb) = read_npy_f32(&dump.join("rgb.npy")).unwrap();
    assert_eq!(shape, vec![240, 320, 3]);
    let target = unseen::io::image::read_png(&tdir.join("view_05.png")).unwrap();
    let l1 = rgb
        .iter()
        .zip(&target.data)
        .map(|(a, b)| (a - b).abs() as f64)
        .sum::<f64>()
        / rgb.len() as f64;
    let (lshape, loss) = read_npy_f32(&dump.join("loss.npy")).unwrap();
    assert!(lshape.is_empty());
    assert!((loss[0] as f64 - l1).abs() < 1e-6, "{} vs {l1}", loss[0]);
    let (gshape, _) = read_npy_f32(&dump.join("grad_sh_rest.npy")).unwrap();
    assert_eq!(gshape, vec![7075, 3, 3]);
}

/// `l1-dssim` is INRIA's 0.8·L1 + 0.2·(1 − SSIM), and its image gradient is the same mix.
#[test]
fn oracle_l1_dssim_loss() {
    use unseen::oracle::{Loss, Targets, dump};
    use unseen::raster::{Outputs, RenderOptions, render};
    use unseen::scene::{default_camera, random_scene};
    let scene = random_scene(400, 1, 4, 0.01, 0.2);
    let cam = default_camera(40, 30);
    let target: Vec<f32> = (0..40 * 30 * 3)
        .map(|i| ((i * 37) % 101) as f32 / 100.0)
        .collect();
    let dir = crate::support::TempDir::path_only("oracle-ssim");
    let t = Targets {
        rgb: &target,
        loss: Loss::L1DSsim,
        depth: None,
    };
    dump(&scene, &cam, &RenderOptions::default(), Some(&t), &dir).unwrap();
    let rgb = render(
        &scene,
        &cam,
        &RenderOptions {
            outputs: Outputs::RGB,
            ..Default::default()
        },
    )
    .unwrap()
    .rgb
    .unwrap();
    let l1 = rgb
        .iter()
        .zip(&target)
        .map(|(a, b)| (a - b).abs() as f64)
        .sum::<f64>()
        / rgb.len() as f64;
    let (s, _) = unseen::train::ssim::ssim(&rgb, &target, 40, 30, 3, false);
    let want = 0.8 * l1 + 0.2 * (1.0 - s);
    let (_, loss) = read_npy_f32(&dir.join("loss.npy")).unwrap();
    assert!(
        (loss[0] as f64 - want).abs() < 1e-6,
        "{} vs {want}",
        loss[0]
    );
}

/// `unseen compare` on folders of oracle dumps (manifests that name no pipeline step):
/// each dump is a step named by its folder, so a changed value is found in it. (It used
/// the manifests' empty step name and compared the run's root instead.)
#[test]
fn compare_names_oracle_dumps_by_their_folder() {
    use unseen::camera::inria::read_cameras_json;
    use unseen::gaussian::ply::read_ply;
    use unseen::pipeline::compare::compare;
    let demo = reference("demo");
    let t = crate::support::TempDir::new("oracle-compare");
    let (scene, _) = read_ply(&demo.join("scene.ply")).unwrap();
    let cam = read_cameras_json(&demo.join("cameras.json"))
        .unwrap()
        .remove(0);
    let opts = unseen::raster::RenderOptions::default();
    for run in ["a", "b"] {
        unseen::oracle::dump(&scene, &cam, &opts, None, &t.path().join(run).join("fwd")).unwrap();
    }
    let same = compare(&t.path().join("a"), &t.path().join("b"), 0.0).unwrap();
    assert!(same.first_divergent.is_none(), "{}", same.table());
    assert_eq!(same.steps.len(), 1);
    assert_eq!(same.steps[0].step, "fwd");
    let rgb = t.path().join("b/fwd/rgb.npy");
    let (shape, mut v) = unseen::io::npy::read_npy_f32(&rgb).unwrap();
    v[10] += 0.5;
    unseen::io::npy::write_npy(&rgb, &v, &shape).unwrap();
    let c = compare(&t.path().join("a"), &t.path().join("b"), 0.0).unwrap();
    assert_eq!(c.first_divergent.as_deref(), Some("fwd"), "{}", c.table());
    // f32 .npy arrays are compared by value.
    let f = c.steps[0]
        .files
        .iter()
        .find(|f| f.path == "rgb.npy")
        .unwrap();
    assert!((f.max_abs.unwrap() - 0.5).abs() < 1e-6, "{f:?}");
    assert!(
        compare(&t.path().join("a"), &t.path().join("b"), 0.6)
            .unwrap()
            .first_divergent
            .is_none()
    );
}

/// `unseen oracle adam`: every step's parameters and moments as .npy, the bits of
/// `adam_trace` under the chosen constants, with a manifest; gradients of the wrong width
/// are one clear error naming the file.
#[test]
fn oracle_adam_dumps_every_step_and_refuses_wrong_shapes() {
    use unseen::io::npy::write_npy;
    use unseen::train::adam::{Constants, adam_trace};
    let t = crate::support::TempDir::new("oracle-adam");
    let x0 = [0.5f32, -1.0, 2.0e-3];
    let grads = [0.1f32, -0.2, 1e-16, 0.05, 0.0, -3e-15, 1.0, 0.5, 0.0];
    write_npy(&t.path().join("x.npy"), &x0, &[3]).unwrap();
    write_npy(&t.path().join("g.npy"), &grads, &[3, 3]).unwrap();
    write_npy(&t.path().join("bad.npy"), &grads, &[9]).unwrap();
    // `--constants`, and for the trainer's its older spelling `--conventions`.
    let run = |grads: &str, constants: &str, out: &str| {
        let flag = if constants == "unseen" {
            "--conventions"
        } else {
            "--constants"
        };
        Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(["oracle", "adam", "--lr", "0.01", flag, constants])
            .arg("--params")
            .arg(t.path().join("x.npy"))
            .arg("--grads")
            .arg(t.path().join(grads))
            .arg("--out")
            .arg(t.path().join(out))
            .output()
            .unwrap()
    };
    for (conventions, constants) in [
        ("pytorch", Constants::PyTorch),
        ("unseen", Constants::Unseen),
    ] {
        let o = run("g.npy", conventions, conventions);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let want = adam_trace([0.9, 0.999], 1e-15, 0.01, constants, &x0, &grads).unwrap();
        let dir = t.path().join(conventions);
        for (name, w) in [
            ("params", &want.x),
            ("exp_avg", &want.m),
            ("exp_avg_sq", &want.v),
        ] {
            let (shape, got) = read_npy_f32(&dir.join(format!("{name}.npy"))).unwrap();
            assert_eq!(shape, [3, 3], "{name}");
            assert_eq!(
                got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                w.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                "{conventions}: {name}"
            );
        }
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap();
        assert_eq!(m["inputs"]["constants"], conventions, "{m}");
    }
    let o = run("bad.npy", "pytorch", "bad");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("bad.npy") && err.contains("(S, 3)"), "{err}");
    assert!(!t.path().join("bad").exists());
    let o = run("g.npy", "keras", "keras");
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown conventions 'keras'"));
}

/// `unseen oracle inpaint`: the traced Telea fill of an 8-bit PNG (OpenCV's values, bit
/// for bit) and of a float .npy as .npy files with a manifest; a forced port of another
/// size is one clear error naming its file, and nothing is written.
#[test]
fn oracle_inpaint_dumps_the_trace_and_refuses_a_forced_image_of_another_size() {
    use unseen::io::npy::write_npy;
    let t = crate::support::TempDir::new("oracle-inpaint");
    let case = reference("opencv/telea/rgb_blobs_r3");
    let run = |args: &[&std::ffi::OsStr]| {
        Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(["oracle", "inpaint"])
            .args(args)
            .output()
            .unwrap()
    };
    let out = t.path().join("png");
    let o = run(&[
        case.join("input.png").as_os_str(),
        case.join("mask.png").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["inputs"]["dtype"], "|u1", "{m}");
    let image = std::fs::read(out.join("image.npy")).unwrap();
    let want = image::open(case.join("expected.png"))
        .unwrap()
        .into_rgb8()
        .into_raw();
    assert_eq!(
        &image[image.len() - want.len()..],
        &want[..],
        "OpenCV's bits"
    );
    let (shape, bound) = read_npy_f32(&out.join("bound.npy")).unwrap();
    assert_eq!(shape[2], 3);
    assert!(bound.iter().all(|b| b.is_finite() && *b >= 0.0));
    // Float32 gray .npy.
    let (w, h) = (20usize, 12usize);
    let img: Vec<f32> = (0..w * h).map(|i| ((i * 7) % 13) as f32 / 13.0).collect();
    let mask: Vec<f32> = (0..w * h)
        .map(|i| ((4..9).contains(&(i % w)) && (3..8).contains(&(i / w))) as u8 as f32)
        .collect();
    write_npy(&t.path().join("img.npy"), &img, &[h, w]).unwrap();
    write_npy(&t.path().join("mask.npy"), &mask, &[h, w]).unwrap();
    write_npy(
        &t.path().join("small.npy"),
        &img[..w * (h - 1)],
        &[h - 1, w],
    )
    .unwrap();
    let out = t.path().join("npy");
    let o = run(&[
        t.path().join("img.npy").as_os_str(),
        t.path().join("mask.npy").as_os_str(),
        "--radius".as_ref(),
        "2".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (shape, got) = read_npy_f32(&out.join("image.npy")).unwrap();
    assert_eq!(shape, [h, w, 1]);
    let fill: Vec<bool> = mask.iter().map(|&m| m != 0.0).collect();
    let want = unseen::models::telea::inpaint(&img, w, h, 1, &fill, 2.0).unwrap();
    assert_eq!(
        got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        want.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    let bad = t.path().join("bad");
    let o = run(&[
        t.path().join("img.npy").as_os_str(),
        t.path().join("mask.npy").as_os_str(),
        "--forced".as_ref(),
        t.path().join("small.npy").as_os_str(),
        "--out".as_ref(),
        bad.as_os_str(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("small.npy") && err.contains("20x11x1"),
        "{err}"
    );
    assert!(!bad.exists());
}

/// `unseen oracle warp`: the traced warp of a bundled pair as .npy, the library's warp bit
/// for bit, with the projections and the set-aside pixels; a missing depth file is one
/// clear error naming it, and nothing is written.
#[test]
fn oracle_warp_dumps_the_traced_warp() {
    use unseen::camera::{find, inria::read_cameras_json};
    use unseen::io::image::{read_exr, read_png};
    use unseen::warp::dibr::{Footprint, WarpOptions, warp};
    let t = crate::support::TempDir::new("oracle-warp");
    let root = reference("scenes/lounge");
    let (a, b) = ("train_013", "train_035");
    let run = |depth: &std::path::Path, out: &std::path::Path| {
        Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args([
                "oracle",
                "warp",
                "--from",
                a,
                "--to",
                b,
                "--footprint",
                "bilinear",
            ])
            .arg("--image")
            .arg(root.join(format!("images/{a}.png")))
            .arg("--depth")
            .arg(depth)
            .arg("--cameras")
            .arg(root.join("cameras.json"))
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let out = t.path().join("dump");
    let o = run(&root.join(format!("depth/{a}.exr")), &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cams = read_cameras_json(&root.join("cameras.json")).unwrap();
    let p = root.join("cameras.json");
    let (from, to) = (find(&cams, a, &p).unwrap(), find(&cams, b, &p).unwrap());
    let image = read_png(&root.join(format!("images/{a}.png"))).unwrap();
    let depth = read_exr(&root.join(format!("depth/{a}.exr")), &["Y"])
        .unwrap()
        .data;
    let opts = WarpOptions {
        footprint: Footprint::Bilinear,
        ..WarpOptions::default()
    };
    let want = warp(&image, &depth, from, to, &opts).unwrap();
    let (shape, got) = read_npy_f32(&out.join("image.npy")).unwrap();
    assert_eq!(
        shape,
        [to.height as usize, to.width as usize, image.channels]
    );
    assert_eq!(
        crate::support::bits(&got),
        crate::support::bits(&want.image.data)
    );
    let (_, z) = read_npy_f32(&out.join("depth.npy")).unwrap();
    assert_eq!(crate::support::bits(&z), crate::support::bits(&want.depth));
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["inputs"]["options"]["footprint"], "bilinear", "{m}");
    // The rest as the library traces it: raw little-endian payloads at each file's end.
    let traced = unseen::warp::dibr::warp_traced(&image, &depth, from, to, &opts).unwrap();
    let payload = |name: &str, want: Vec<u8>| {
        let bytes = std::fs::read(out.join(format!("{name}.npy"))).unwrap();
        assert_eq!(&bytes[bytes.len() - want.len()..], &want[..], "{name}");
    };
    payload(
        "holes",
        traced.warped.holes.iter().map(|&h| h as u8).collect(),
    );
    payload("aside", traced.aside.clone());
    payload("u", traced.u.iter().flat_map(|v| v.to_le_bytes()).collect());
    payload("v", traced.v.iter().flat_map(|v| v.to_le_bytes()).collect());
    payload("z", traced.z.iter().flat_map(|v| v.to_le_bytes()).collect());
    assert!(
        traced.aside.iter().any(|&a| a != 0),
        "a real pair has pixels near a decision"
    );
    let bad = t.path().join("bad");
    let o = run(&t.path().join("missing.exr"), &bad);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("missing.exr"), "{err}");
    assert!(!bad.exists());
}

/// `unseen oracle densify`: one step of a random scene with given statistics and draws as
/// .npy, the library's step bit for bit, the counts in the manifest; counts that are not
/// whole numbers are one clear error naming the file, and nothing is written.
#[test]
fn oracle_densify_dumps_the_step_and_refuses_fractional_counts() {
    use unseen::io::npy::write_npy;
    use unseen::train::adam::{Adam, AdamConfig};
    use unseen::train::densify::{DensifyConfig, DensifyStats, Normals, densify_and_prune};
    let t = crate::support::TempDir::new("oracle-densify");
    let g = unseen::scene::random_scene(300, 3, 7, 0.005, 0.3);
    unseen::gaussian::ply::write_ply(&g, &t.path().join("scene.ply")).unwrap();
    let n = g.len();
    let mut u = unseen::rng::Uniform::new(3);
    let count: Vec<f32> = (0..n).map(|_| (u.unit() * 4.0).floor()).collect();
    let acc: Vec<f32> = count.iter().map(|&c| c * 4e-4 * u.unit()).collect();
    let z: Vec<f32> = (0..2 * n * 3).map(|_| u.normal()).collect();
    write_npy(&t.path().join("acc.npy"), &acc, &[n]).unwrap();
    write_npy(&t.path().join("count.npy"), &count, &[n]).unwrap();
    write_npy(&t.path().join("half.npy"), &vec![0.5f32; n], &[n]).unwrap();
    write_npy(&t.path().join("z.npy"), &z, &[2, n, 3]).unwrap();
    let run = |count: &str, out: &str| {
        Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(["oracle", "densify", "--extent", "4", "--world-prune"])
            .arg(t.path().join("scene.ply"))
            .arg("--grad-accum")
            .arg(t.path().join("acc.npy"))
            .arg("--count")
            .arg(t.path().join(count))
            .arg("--normals")
            .arg(t.path().join("z.npy"))
            .arg("--out")
            .arg(t.path().join(out))
            .output()
            .unwrap()
    };
    let o = run("count.npy", "dump");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (mut want, mut adam) = (g.clone(), Adam::new(AdamConfig::default(), &g).unwrap());
    let mut stats = DensifyStats {
        grad_accum: acc.clone(),
        count: count.iter().map(|&c| c as u32).collect(),
        max_radius: vec![0.0; n],
    };
    let z3: Vec<[f32; 3]> = z.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let r = densify_and_prune(
        &mut want,
        &mut adam,
        &mut stats,
        &DensifyConfig::default(),
        4.0,
        true,
        Normals::Given(&z3),
        None,
    )
    .unwrap();
    assert!(r.cloned > 0 && r.split > 0, "{r:?}");
    let dir = t.path().join("dump");
    let (shape, means) = read_npy_f32(&dir.join("means.npy")).unwrap();
    assert_eq!(shape, [want.len(), 3]);
    let flat: Vec<f32> = want.means.concat();
    assert_eq!(crate::support::bits(&means), crate::support::bits(&flat));
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["inputs"]["report"]["split"], r.split, "{m}");
    let o = run("half.npy", "bad");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("half.npy") && err.contains("whole"),
        "{err}"
    );
    assert!(!t.path().join("bad").exists());
}

/// `unseen oracle align`: per pixel the relative residual and inlier flag of the library's
/// fit, the fit in the manifest; an unknown method is one clear error.
#[test]
fn oracle_align_dumps_residuals_and_inliers() {
    use unseen::io::npy::write_npy;
    use unseen::warp::align::{Frame, RansacConfig, Space, ransac};
    let t = crate::support::TempDir::new("oracle-align");
    let mut u = unseen::rng::Uniform::new(9);
    let d: Vec<f32> = (0..400).map(|_| 0.5 + 4.0 * u.unit()).collect();
    let r: Vec<f32> = d
        .iter()
        .enumerate()
        .map(|(i, &d)| {
            if i % 5 == 0 {
                u.unit()
            } else {
                (1.0 / d - 0.1) / 2.0
            }
        })
        .collect();
    write_npy(&t.path().join("r.npy"), &r, &[20, 20]).unwrap();
    write_npy(&t.path().join("d.npy"), &d, &[20, 20]).unwrap();
    let run = |method: &str, out: &str| {
        Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(["oracle", "align", "--method", method])
            .arg(t.path().join("r.npy"))
            .arg(t.path().join("d.npy"))
            .arg("--out")
            .arg(t.path().join(out))
            .output()
            .unwrap()
    };
    let o = run("ransac", "dump");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit = ransac(
        &[Frame {
            estimate: &r,
            depth: &d,
        }],
        Space::Disparity,
        &RansacConfig::default(),
    )
    .unwrap();
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(t.path().join("dump/manifest.json")).unwrap())
            .unwrap();
    assert_eq!(m["inputs"]["fit"]["inliers"], fit.inliers, "{m}");
    let (shape, res) = read_npy_f32(&t.path().join("dump/residual.npy")).unwrap();
    assert_eq!(shape, [20, 20]);
    let inl = std::fs::read(t.path().join("dump/inlier.npy")).unwrap();
    let flags = &inl[inl.len() - 400..];
    assert_eq!(flags.iter().filter(|&&f| f == 1).count(), fit.inliers);
    assert!(
        res.iter()
            .zip(flags)
            .all(|(&r, &f)| (f == 1) == (r as f64 <= 0.05))
    );
    let o = run("irls", "bad");
    assert!(String::from_utf8_lossy(&o.stderr).contains("expected ransac or least_squares"));
    assert!(!t.path().join("bad").exists());
}

/// `unseen oracle qa-mask`: the mask of a mask scene for one camera as .npy, the library's
/// bits, with the colour it projects; an unknown colour name is one clear error.
#[test]
fn oracle_qa_mask_dumps_the_mask_and_its_colour() {
    use unseen::qamask::{QaMaskConfig, mask_scene, render_qa_mask};
    let t = crate::support::TempDir::new("oracle-qa-mask");
    let demo = reference("demo");
    let (trained, _) = unseen::gaussian::ply::read_ply(&demo.join("scene.ply")).unwrap();
    let cfg = QaMaskConfig::default();
    let mut m = mask_scene(&trained, &cfg).unwrap();
    for (k, v) in m.sh_rest.iter_mut().enumerate() {
        *v = ((k * 37 % 101) as f32 / 101.0 - 0.5) * 0.4; // as a fine-tune leaves it
    }
    unseen::gaussian::ply::write_ply(&m, &t.path().join("mask.ply")).unwrap();
    let run = |base: &str, out: &str| {
        Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args(["oracle", "qa-mask", "--base", base])
            .arg(t.path().join("mask.ply"))
            .arg("--cameras")
            .arg(demo.join("cameras.json"))
            .arg("--out")
            .arg(t.path().join(out))
            .output()
            .unwrap()
    };
    let o = run("red", "dump");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cams = unseen::camera::inria::read_cameras_json(&demo.join("cameras.json")).unwrap();
    let want = render_qa_mask(&m, &cams[0], &cfg).unwrap();
    let (shape, got) = read_npy_f32(&t.path().join("dump/mask.npy")).unwrap();
    assert_eq!(shape, [cams[0].height as usize, cams[0].width as usize]);
    assert_eq!(crate::support::bits(&got), crate::support::bits(&want));
    assert!(got.iter().any(|&v| v > 0.0 && v < 1.0));
    let o = run("mauve", "bad");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("mauve"), "{err}");
    assert!(!t.path().join("bad").exists());
}
