//! The `unseen` binary: outputs, and one clear error line for bad input.
use super::common::reference;
use std::path::PathBuf;
use std::process::Command;
use unseen::io::image::{read_exr, read_png};

fn unseen() -> Command {
    Command::new(env!("CARGO_BIN_EXE_unseen"))
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("unseen-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
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
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "render".into(),
                "/nonexistent/s.ply".into(),
                "--cameras".into(),
                demo.join("cameras.json").display().to_string(),
                "--out".into(),
                "/tmp/x".into(),
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
                "/tmp/x".into(),
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
                "/tmp/x".into(),
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
