//! The `unseen` binary: outputs, and one clear error line for bad input.
use crate::support::{TempDir, reference};
use std::path::PathBuf;
use std::process::Command;
use unseen::io::image::{read_exr, read_png};

fn unseen() -> Command {
    Command::new(env!("CARGO_BIN_EXE_unseen"))
}

/// A free path for an output, removed when the guard drops.
fn out_dir(name: &str) -> TempDir {
    TempDir::path_only(&format!("cli-{name}"))
}

#[test]
fn cli_render_writes_png_and_exr() {
    let demo = reference("demo");
    let out = out_dir("render");
    let st = unseen()
        .args([
            "render",
            demo.join("scene.ply").to_str().unwrap(),
            "--cameras",
        ])
        .arg(demo.join("cameras.json"))
        .args([
            "--camera",
            "view_03",
            "--outputs",
            "rgb,alpha,depth,expected_depth",
            "--out",
        ])
        .arg(&out)
        .args(["--background", "0,0,1"])
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let png = read_png(&out.join("view_03.png")).unwrap();
    assert_eq!((png.width, png.height, png.channels), (320, 240, 3));
    let rgb = read_exr(&out.join("view_03.rgb.exr"), &["R", "G", "B"]).unwrap();
    for (p, e) in png.data.iter().zip(&rgb.data) {
        assert_eq!(*p, unseen::io::image::to_u8(*e) as f32 / 255.0);
    }
    for f in ["alpha", "depth", "expected_depth"] {
        let img = read_exr(&out.join(format!("view_03.{f}.exr")), &["Y"]).unwrap();
        assert_eq!((img.width, img.height), (320, 240));
    }
    // No temporary files left behind.
    for e in std::fs::read_dir(&out).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.starts_with('.'), "leftover {name}");
    }
}

#[test]
fn cli_errors_name_the_file() {
    let demo = reference("demo");
    // Never written (every case fails before any output); a guard removes it if one did.
    let out = TempDir::path_only("cli-errors");
    let out_arg = out.display().to_string();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "render".into(),
                "/nonexistent/s.ply".into(),
                "--cameras".into(),
                demo.join("cameras.json").display().to_string(),
                "--out".into(),
                out_arg.clone(),
            ],
            "/nonexistent/s.ply",
        ),
        (
            vec![
                "render".into(),
                demo.join("scene.ply").display().to_string(),
                "--cameras".into(),
                demo.join("scene.ply").display().to_string(),
                "--out".into(),
                out_arg.clone(),
            ],
            "scene.ply: not an INRIA cameras.json",
        ),
        (
            vec![
                "render".into(),
                demo.join("scene.ply").display().to_string(),
                "--cameras".into(),
                demo.join("cameras.json").display().to_string(),
                "--camera".into(),
                "nope".into(),
                "--out".into(),
                out_arg.clone(),
            ],
            "no camera named 'nope'",
        ),
    ];
    for (args, needle) in cases {
        let o = unseen().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert!(err.contains(needle) && err.contains("error: "), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "a failed command wrote {}", out.display());
    }
}

/// `RAYON_NUM_THREADS` = 1, 2, 7: the written files are byte-identical.
#[test]
fn cli_outputs_do_not_depend_on_rayon_num_threads() {
    let demo = reference("demo");
    let mut previous: Option<Vec<Vec<u8>>> = None;
    for threads in ["1", "2", "7"] {
        let out = out_dir(&format!("threads-{threads}"));
        let st = unseen()
            .env("RAYON_NUM_THREADS", threads)
            .args([
                "render",
                demo.join("scene.ply").to_str().unwrap(),
                "--cameras",
            ])
            .arg(demo.join("cameras.json"))
            .args([
                "--outputs",
                "rgb,alpha,depth,expected_depth",
                "--background",
                "0.1,0.2,0.3",
                "--out",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(st.status.success());
        let mut names: Vec<_> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        names.sort();
        assert_eq!(names.len(), 8 * 5);
        let bytes: Vec<Vec<u8>> = names.iter().map(|p| std::fs::read(p).unwrap()).collect();
        if let Some(prev) = &previous {
            assert!(
                prev == &bytes,
                "RAYON_NUM_THREADS={threads} changed the output"
            );
        }
        previous = Some(bytes);
    }
}

/// `unseen train` writes INRIA's layout with a manifest whose hashes match the files, and
/// `unseen eval` scores the run; `unseen demo` runs end to end on a tiny preset.
#[test]
fn cli_train_eval_and_demo() {
    let scene = reference("scenes/lounge");
    let run = out_dir("train");
    let st = unseen()
        .arg("train")
        .arg(&scene)
        .arg("--out")
        .arg(&run)
        .args(["--iterations", "30", "--resolution", "4", "--seed", "7"])
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let ply = run.join("point_cloud/iteration_30/point_cloud.ply");
    let (g, _) = unseen::gaussian::ply::read_ply(&ply).unwrap();
    assert!(g.len() > 1000);
    let cams = unseen::camera::inria::read_cameras_json(&run.join("cameras.json")).unwrap();
    assert_eq!(
        (cams.len(), cams[0].width),
        (96, 40),
        "72 views and 24 bridge views"
    );
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["inputs"]["seed"], 7);
    let files = manifest["files"].as_array().unwrap();
    assert_eq!(files.len(), 4);
    let args = std::fs::read_to_string(run.join("cfg_args")).unwrap();
    assert!(
        args.starts_with("Namespace(sh_degree=3, source_path="),
        "{args}"
    );
    for f in files {
        let bytes = std::fs::read(run.join(f["path"].as_str().unwrap())).unwrap();
        assert_eq!(
            f["sha256"].as_str().unwrap(),
            unseen::io::sha256_hex(&bytes)
        );
    }
    let cfg: unseen::train::trainer::TrainConfig =
        serde_json::from_slice(&std::fs::read(run.join("config.json")).unwrap()).unwrap();
    assert_eq!((cfg.iterations, cfg.resolution), (30, 4));
    // Costs per stage and the iterations' time split (SPEC.md §14.6).
    let stats: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("train_stats.json")).unwrap()).unwrap();
    let stages: Vec<&str> = stats["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s[0].as_str().unwrap())
        .collect();
    assert_eq!(stages, ["load", "train"]);
    let split = &stats["iteration_seconds"];
    let parts =
        ["forward", "loss", "backward", "densify", "adam"].map(|k| split[k].as_f64().unwrap());
    let wall = stats["wall_seconds"].as_f64().unwrap();
    assert!(
        parts.iter().all(|&p| p >= 0.0) && parts.iter().sum::<f64>() <= wall,
        "{split}"
    );
    assert!(parts[0] > 0.0 && parts[2] > 0.0, "{split}");

    let st = unseen()
        .arg("eval")
        .arg(&run)
        .arg("--dataset")
        .arg(&scene)
        .args(["--split", "heldout"])
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let eval: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("eval.json")).unwrap()).unwrap();
    assert_eq!(eval["heldout"]["views"].as_array().unwrap().len(), 36);
    let side = read_png(&run.join("eval/heldout/heldout_000.png")).unwrap();
    assert_eq!((side.width, side.height), (80, 30));

    // The demo with the pipeline shrunk to seconds (its quick preset takes minutes).
    let demo = out_dir("demo");
    let tiny = demo.with_extension("json");
    std::fs::write(
        &tiny,
        r#"{"slots": {"inpaint": "truth", "depth": "truth", "video": "truth",
             "video_depth": "truth", "fixer": "truth"},
            "qa_iterations": 20, "video_frames": 3,
            "stage1": {"iterations": 30, "densify": null},
            "stage2": {"iterations": 30, "densify": null},
            "interpolate": {"iterations": 20, "densify": null}}"#,
    )
    .unwrap();
    let st = unseen()
        .args(["demo", "--iterations", "100", "--config"])
        .arg(&tiny)
        .arg("--out")
        .arg(&demo)
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&tiny);
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let report = std::fs::read_to_string(demo.join("report.md")).unwrap();
    assert!(
        report.contains("## Metrics") && report.contains("ground-truth generator"),
        "{report}"
    );
    assert!(
        demo.join("extrapolate/interpolate/recon/scene.ply")
            .is_file()
    );
    let _ = std::fs::remove_dir_all(&demo);
}

/// A directory that is no dataset, and a broken config, are one clear error line.
#[test]
fn cli_train_rejects_bad_input() {
    let run = out_dir("bad-train");
    let st = unseen()
        .arg("train")
        .arg(reference("drjit"))
        .arg("--out")
        .arg(&run)
        .output()
        .unwrap();
    assert!(!st.status.success());
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(err.contains("is not a dataset"), "{err}");
    let cfg = out_dir("bad-config.json");
    std::fs::write(&cfg, "{\"iterations\": \"many\"}").unwrap();
    let st = unseen()
        .arg("train")
        .arg(reference("scenes/lounge"))
        .arg("--out")
        .arg(&run)
        .arg("--config")
        .arg(&cfg)
        .output()
        .unwrap();
    assert!(!st.status.success());
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(
        err.contains("bad-config.json") && err.contains("invalid train config"),
        "{err}"
    );
    assert!(
        !run.join("point_cloud").exists(),
        "nothing written on bad input"
    );
}

/// `unseen qa-mask`, `unseen render --mask` (QA and a baseline) and a masked fine-tune
/// `unseen train --init RUN --mask qa` on a tiny run.
#[test]
fn cli_qa_mask_render_mask_and_masked_fine_tune() {
    let scene = reference("scenes/lounge");
    let run = out_dir("qa-run");
    let ok = |st: std::process::Output| {
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
    };
    ok(unseen()
        .arg("train")
        .arg(&scene)
        .arg("--out")
        .arg(&run)
        .args(["--iterations", "20", "--resolution", "4"])
        .output()
        .unwrap());
    let qa = out_dir("qa-dir");
    ok(unseen()
        .arg("qa-mask")
        .arg(&run)
        .arg("--out")
        .arg(&qa)
        .args([
            "--sh-degree",
            "3",
            "--iterations",
            "30",
            "--colors",
            "green,#000000",
        ])
        .output()
        .unwrap());
    let (g, cfg) = unseen::qamask::read_mask_dir(&qa).unwrap();
    assert_eq!(
        (g.sh_degree, cfg.base_color, cfg.iterations),
        (3, [0.0, 1.0, 0.0], 30)
    );
    let masks = out_dir("qa-masks");
    ok(unseen()
        .arg("render")
        .arg("--cameras")
        .arg(run.join("cameras.json"))
        .args(["--camera", "heldout_004", "--mask"])
        .arg(&qa)
        .arg("--out")
        .arg(&masks)
        .output()
        .unwrap());
    let m = read_exr(&masks.join("heldout_004.mask.exr"), &["Y"]).unwrap();
    assert_eq!((m.width, m.height), (40, 30));
    assert!(m.data.iter().all(|v| (0.0..=1.0).contains(v)));
    let heat = read_png(&masks.join("heldout_004.mask.png")).unwrap();
    assert_eq!(heat.channels, 3);
    ok(unseen()
        .arg("render")
        .arg(run.join("point_cloud/iteration_20/point_cloud.ply"))
        .arg("--cameras")
        .arg(run.join("cameras.json"))
        .args(["--camera", "train_001", "--mask", "opacity", "--out"])
        .arg(&masks)
        .output()
        .unwrap());
    assert!(masks.join("train_001.mask.exr").is_file());
    let tuned = out_dir("qa-tuned");
    ok(unseen()
        .arg("train")
        .arg(&scene)
        .arg("--out")
        .arg(&tuned)
        .arg("--init")
        .arg(&run)
        .args(["--mask", "qa", "--mask-dir"])
        .arg(&qa)
        .args(["--iterations", "10", "--resolution", "4"])
        .output()
        .unwrap());
    let cfg: unseen::train::trainer::TrainConfig =
        serde_json::from_slice(&std::fs::read(tuned.join("config.json")).unwrap()).unwrap();
    assert_eq!(cfg.loss, unseen::train::loss::LossWeights::PAPER);
    let audit = out_dir("qa-audit.json");
    ok(unseen()
        .arg("mask-audit")
        .arg(&run)
        .arg("--dataset")
        .arg(&scene)
        .args(["--degrees", "3", "--iterations", "10", "--out"])
        .arg(&audit)
        .output()
        .unwrap());
    let a: serde_json::Value = serde_json::from_slice(&std::fs::read(&audit).unwrap()).unwrap();
    assert_eq!(a["report"]["rows"].as_array().unwrap().len(), 3);
    assert_eq!(a["report"]["heldout_pixels"], 36 * 40 * 30);
    // A mask without a run to fine-tune is refused.
    let st = unseen()
        .arg("train")
        .arg(&scene)
        .arg("--out")
        .arg(out_dir("qa-bad"))
        .args(["--mask", "opacity"])
        .output()
        .unwrap();
    assert!(!st.status.success());
    assert!(String::from_utf8_lossy(&st.stderr).contains("--init"));
}

/// `unseen warp`, `unseen collide` and `unseen views`: outputs equal the library's,
/// formats as documented, bad input is one clear error line naming the file.
#[test]
fn cli_warp_collide_and_views() {
    use unseen::camera::inria::read_cameras_json;
    use unseen::warp::dibr::{WarpOptions, warp};
    let root = reference("scenes/lounge");
    let out = out_dir("geometry");
    std::fs::create_dir_all(&out).unwrap();
    // warp
    let (a, b) = ("heldout_025", "heldout_033");
    let st = unseen()
        .arg("warp")
        .arg("--image")
        .arg(root.join(format!("images/{a}.png")))
        .arg("--depth")
        .arg(root.join(format!("depth/{a}.exr")))
        .args(["--from", a, "--to", b, "--cameras"])
        .arg(root.join("cameras.json"))
        .args(["--close-cracks", "1", "--out"])
        .arg(out.join("warp"))
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let cams = read_cameras_json(&root.join("cameras.json")).unwrap();
    let cam = |n: &str| cams.iter().find(|c| c.name == n).unwrap();
    let want = warp(
        &read_png(&root.join(format!("images/{a}.png"))).unwrap(),
        &read_exr(&root.join(format!("depth/{a}.exr")), &["Y"])
            .unwrap()
            .data,
        cam(a),
        cam(b),
        &WarpOptions {
            close_cracks: 1,
            ..WarpOptions::default()
        },
    )
    .unwrap();
    let png = read_png(&out.join("warp/warped.png")).unwrap();
    for (p, e) in png.data.iter().zip(&want.image.data) {
        assert_eq!(*p, unseen::io::image::to_u8(*e) as f32 / 255.0);
    }
    assert_eq!(
        read_exr(&out.join("warp/depth.exr"), &["Y"]).unwrap().data,
        want.depth
    );
    let holes = read_png(&out.join("warp/holes.png")).unwrap();
    assert_eq!(
        holes.data.iter().map(|&v| v > 0.5).collect::<Vec<_>>(),
        want.holes
    );
    let st = unseen()
        .arg("warp")
        .arg("--image")
        .arg(root.join(format!("images/{a}.png")))
        .arg("--depth")
        .arg(root.join("missing.exr"))
        .args(["--from", a, "--to", b, "--cameras"])
        .arg(root.join("cameras.json"))
        .arg("--out")
        .arg(out.join("warp-bad"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(!st.status.success() && err.contains("missing.exr"), "{err}");
    assert!(!out.join("warp-bad").exists(), "no partial output");

    // collide
    let cube = |name: &str, o: f64| {
        let p = out.join(name);
        let v: Vec<[f64; 3]> = (0..8)
            .map(|k| {
                [
                    o + (k & 1) as f64,
                    ((k >> 1) & 1) as f64,
                    ((k >> 2) & 1) as f64,
                ]
            })
            .collect();
        std::fs::write(&p, serde_json::json!({ "vertices": v }).to_string()).unwrap();
        p
    };
    let (c0, c1, c3) = (
        cube("c0.json", 0.0),
        cube("c1.json", 0.5),
        cube("c3.json", 3.0),
    );
    let run = |x: &PathBuf, y: &PathBuf| {
        let o = unseen()
            .arg("collide")
            .arg(x)
            .arg(y)
            .arg("--json")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    assert_eq!(run(&c0, &c1)["intersect"], true);
    let far = run(&c0, &c3);
    assert_eq!(far["intersect"], false);
    assert!((far["distance"].as_f64().unwrap() - 2.0).abs() < 1e-12);
    let text = unseen().arg("collide").arg(&c0).arg(&c3).output().unwrap();
    assert!(String::from_utf8_lossy(&text.stdout).starts_with("separated"));
    let bad = out.join("bad.json");
    std::fs::write(&bad, r#"{"vertices": [[0, 0, "x"]]}"#).unwrap();
    let o = unseen().arg("collide").arg(&c0).arg(&bad).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("bad.json"), "{err}");

    // views: three candidates with a block mask each and ranges (one averaged).
    let masks = out.join("masks");
    std::fs::create_dir_all(&masks).unwrap();
    let names = ["heldout_000", "heldout_001", "heldout_002"];
    for n in names {
        let c = cam(n);
        let (w, h) = (c.width as usize, c.height as usize);
        let m: Vec<f32> = (0..w * h)
            .map(|i| {
                if (i % w) > w / 2 && (i / w) < h / 2 {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        unseen::io::image::write_png(
            &masks.join(format!("{n}.png")),
            &unseen::io::image::ImageF32::new(w, h, 1, m).unwrap(),
        )
        .unwrap();
    }
    let ranges = out.join("ranges.json");
    std::fs::write(
        &ranges,
        r#"{"heldout_000": [1.0, 3.0], "heldout_001": [[1.0, 2.0], [2.0, 4.0]], "heldout_002": [0.5, 6.0]}"#,
    )
    .unwrap();
    // `unseen [oracle] views` on these candidates, with a hull outline.
    let views = |command: &[&str], dir: &str| {
        unseen()
            .args(command)
            .arg("--cameras")
            .arg(root.join("cameras.json"))
            .args(["--candidates", &names.join(","), "--masks"])
            .arg(&masks)
            .arg("--depth-ranges")
            .arg(&ranges)
            .args(["--outline", "hull", "--out"])
            .arg(out.join(dir))
            .output()
            .unwrap()
    };
    let st = views(&["views"], "views");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("views/views.json")).unwrap())
            .unwrap();
    assert_eq!(
        v["frustums"][1]["depth_range"],
        serde_json::json!([1.5, 3.0])
    );
    let indep = v["independent"].as_array().unwrap();
    assert_eq!(indep[0], "heldout_000");
    assert_eq!(v["trajectory"].as_array().unwrap().len(), indep.len());
    for pair in v["collisions"].as_array().unwrap() {
        let (x, y) = (&pair[0], &pair[1]);
        assert!(!(indep.contains(x) && indep.contains(y)), "{pair}");
    }
    let (models, _) = tobj::load_obj(
        out.join("views/frustums.obj"),
        &tobj::LoadOptions::default(),
    )
    .unwrap();
    assert_eq!(models.len(), 3);
    // The oracle dumps of the same detection and of one pair (SPEC.md §8.2): the frustums
    // `views` wrote, bit for bit; each pair's verdict and distance as `oracle collide`
    // computes them; the sets by index.
    let st = views(&["oracle", "views"], "oracle-views");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    use unseen::io::npy::read_npy;
    let dump = |name: &str| out.join("oracle-views").join(format!("{name}.npy"));
    let (vs, vertices) = read_npy::<f64>(&dump("vertices")).unwrap();
    let (_, offsets) = read_npy::<u32>(&dump("offsets")).unwrap();
    let (cs, collisions) = read_npy::<u8>(&dump("collisions")).unwrap();
    let (_, distance) = read_npy::<f64>(&dump("distance")).unwrap();
    let (_, independent) = read_npy::<u32>(&dump("independent")).unwrap();
    let (_, trajectory) = read_npy::<u32>(&dump("trajectory")).unwrap();
    let n = names.len();
    assert_eq!((vs[1], cs, offsets.len()), (3, vec![n, n], n + 1));
    for k in 0..n {
        let want: Vec<f64> = v["frustums"][k]["vertices"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|p| p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
            .collect();
        let rows = &vertices[3 * offsets[k] as usize..3 * offsets[k + 1] as usize];
        assert_eq!(rows, &want[..], "frustum {k}");
    }
    let name_of = |i: &u32| serde_json::json!(names[*i as usize]);
    assert_eq!(
        independent.iter().map(name_of).collect::<Vec<_>>(),
        *v["independent"].as_array().unwrap()
    );
    assert_eq!(
        trajectory.iter().map(name_of).collect::<Vec<_>>(),
        *v["trajectory"].as_array().unwrap()
    );
    for i in 0..n {
        for j in i + 1..n {
            let listed = v["collisions"]
                .as_array()
                .unwrap()
                .contains(&serde_json::json!([names[i], names[j]]));
            assert_eq!(collisions[i * n + j] == 1, listed, "pair {i} {j}");
            assert_eq!(collisions[i * n + j], collisions[j * n + i]);
            let hull = |k: usize| {
                let f = out.join(format!("frustum-{k}.json"));
                let vs = &v["frustums"][k]["vertices"];
                std::fs::write(&f, serde_json::json!({ "vertices": vs }).to_string()).unwrap();
                f
            };
            let pair = out.join(format!("oracle-collide-{i}-{j}"));
            let st = unseen()
                .args(["oracle", "collide"])
                .arg(hull(i))
                .arg(hull(j))
                .arg("--out")
                .arg(&pair)
                .output()
                .unwrap();
            assert!(
                st.status.success(),
                "{}",
                String::from_utf8_lossy(&st.stderr)
            );
            let (shape, hit) = read_npy::<u8>(&pair.join("intersect.npy")).unwrap();
            let (_, d) = read_npy::<f64>(&pair.join("distance.npy")).unwrap();
            assert_eq!((shape, hit[0]), (vec![], collisions[i * n + j]));
            assert_eq!(
                d[0].to_bits(),
                distance[i * n + j].to_bits(),
                "pair {i} {j}"
            );
        }
    }

    std::fs::remove_file(masks.join("heldout_001.png")).unwrap();
    let st = views(&["views"], "views-bad");
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(
        !st.status.success() && err.contains("heldout_001.png"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// `unseen inpaint` reproduces cv2.inpaint's PNG (a golden case) and `unseen depth`
/// extends a known depth; bad input names the file.
#[test]
fn cli_inpaint_and_depth() {
    let out = out_dir("models");
    std::fs::create_dir_all(&out).unwrap();
    let case = reference("opencv/telea/rgb_render_scribble_r3");
    let st = unseen()
        .arg("inpaint")
        .arg(case.join("input.png"))
        .arg(case.join("mask.png"))
        .arg("--out")
        .arg(out.join("filled.png"))
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let got = read_png(&out.join("filled.png")).unwrap();
    let want = read_png(&case.join("expected.png")).unwrap();
    assert_eq!(got.data, want.data, "CLI output = cv2.inpaint");
    let st = unseen()
        .arg("inpaint")
        .arg(case.join("input.png"))
        .arg(reference("opencv/telea/gray_frame_r1/mask.png"))
        .arg("--out")
        .arg(out.join("bad.png"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(!st.status.success() && err.contains("mask.png"), "{err}");
    assert!(!out.join("bad.png").exists());
    // depth-fill from a Mitsuba depth with a hole.
    let root = reference("scenes/lounge");
    let mask: Vec<f32> = (0..160 * 120)
        .map(|i| {
            if (40..80).contains(&(i % 160)) && (30..70).contains(&(i / 160)) {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    unseen::io::image::write_png(
        &out.join("hole.png"),
        &unseen::io::image::ImageF32::new(160, 120, 1, mask.clone()).unwrap(),
    )
    .unwrap();
    let st = unseen()
        .arg("depth")
        .arg(root.join("images/train_004.png"))
        .arg("--hint")
        .arg(root.join("depth/train_004.exr"))
        .arg("--hint-mask")
        .arg(out.join("hole.png"))
        .arg("--out")
        .arg(out.join("d.exr"))
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let d = read_exr(&out.join("d.exr"), &["Y"]).unwrap();
    let gt = read_exr(&root.join("depth/train_004.exr"), &["Y"]).unwrap();
    for (p, &m) in mask.iter().enumerate() {
        if m == 0.0 {
            assert_eq!(d.data[p], gt.data[p]);
        } else {
            assert!(d.data[p] > 0.0 && d.data[p].is_finite());
        }
    }
    let st = unseen()
        .arg("depth")
        .arg(root.join("images/train_004.png"))
        .arg("--out")
        .arg(out.join("d2.exr"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(!st.status.success() && err.contains("hint"), "{err}");
    let _ = std::fs::remove_dir_all(&out);
}

/// `unseen render --alpha-threshold / --transmittance-stop` (the forward cut-offs,
/// SPEC.md §5.4): gsplat's values given explicitly give the default's bytes, others change
/// the image, bad values are refused with the flag's problem named.
#[test]
fn cli_render_cutoffs() {
    let demo = reference("demo");
    let run = |extra: &[&str]| {
        let out = out_dir("render-cutoffs");
        let st = unseen()
            .arg("render")
            .arg(demo.join("scene.ply"))
            .arg("--cameras")
            .arg(demo.join("cameras.json"))
            .args(["--camera", "view_03", "--out"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        let png = st
            .status
            .success()
            .then(|| std::fs::read(out.join("view_03.png")).unwrap());
        (png, String::from_utf8_lossy(&st.stderr).into_owned())
    };
    let (default, _) = run(&[]);
    let default = default.expect("default render");
    let (explicit, _) = run(&["--alpha-threshold", "1/255", "--transmittance-stop", "1e-4"]);
    assert_eq!(explicit.as_deref(), Some(&default[..]));
    let (exact, err) = run(&["--alpha-threshold", "0", "--transmittance-stop", "0"]);
    let exact = exact.unwrap_or_else(|| panic!("{err}"));
    assert_ne!(exact, default, "no cut-offs changed nothing");
    for (flags, needle) in [
        (["--alpha-threshold", "0.5"], "1/N"),
        (["--alpha-threshold", "1/0.5"], "N ≥ 1"),
        (["--transmittance-stop", "1.5"], "transmittance stop"),
    ] {
        let (png, err) = run(&flags);
        assert!(png.is_none(), "{flags:?} accepted");
        assert!(err.contains(needle), "{flags:?}: {err}");
    }
}

/// `UNSEEN_MAX_ISA` caps the instruction set of every kernel (projection, blends, their
/// backward, SSIM, Adam): training under AVX2 or the scalar forms writes the same bytes as
/// under the CPU's widest, and a value it does not know is named on stderr and ignored.
#[test]
fn the_isa_cap_changes_no_bit_of_training() {
    let lounge = crate::support::tiny_run::lounge();
    let out = out_dir("isa-cap");
    let train = |cap: &str| {
        let dir = out.join(if cap.is_empty() { "widest" } else { cap });
        let o = unseen()
            .env(unseen::raster::kernel::MAX_ISA_VAR, cap)
            .arg("train")
            .arg(&lounge)
            .arg("--out")
            .arg(&dir)
            .args(["--iterations", "60", "--resolution", "4"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let ply = std::fs::read(dir.join("point_cloud/iteration_60/point_cloud.ply")).unwrap();
        (ply, String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let (widest, _) = train("");
    for cap in ["avx2", "scalar"] {
        assert!(train(cap).0 == widest, "{cap}: another scene");
    }
    let (same, err) = train("sse9");
    assert!(same == widest);
    assert!(
        err.contains("UNSEEN_MAX_ISA=\"sse9\" is not one of"),
        "{err}"
    );
}
