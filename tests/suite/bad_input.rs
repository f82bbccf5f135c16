//! The bad-input matrix (SPEC.md §11): every subcommand, fed a missing, empty, truncated or
//! wrong-kind file in each of its inputs (and in the files inside its dataset and run
//! folders), a NaN in a scene, numbers out of range, an image of the wrong size, a camera
//! with fx = 0, an output path that is a file or cannot be created, exits with 1
//! (`compare`: 2), prints exactly one `error:` line naming the file, never panics, and
//! leaves no partial output: nothing at the destination (or the file that was there,
//! unchanged) and no `.tmp` file.
use crate::support::{TempDir, reference};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

/// What a file input holds, which decides its bad variants.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Kind {
    /// Any JSON document.
    Json,
    /// INRIA cameras.json (also: a position out of range, fx = 0).
    Cameras,
    /// Binary PLY (also: a NaN in the first vertex).
    Ply,
    /// PNG whose size must match its camera or partner image (also: 3×3).
    Png,
    /// Single-channel EXR whose size must match (also: 3×3).
    Exr,
    /// A folder (missing; a file in its place); its files are slots of their own.
    Dir,
}

/// An input of a command: a name used in its arguments, the valid path, its kind, and for
/// a folder the files inside it to spoil one at a time.
struct Input {
    name: &'static str,
    path: PathBuf,
    kind: Kind,
    inner: Vec<(&'static str, Kind)>,
}

fn input(name: &'static str, path: PathBuf, kind: Kind) -> Input {
    Input {
        name,
        path,
        kind,
        inner: vec![],
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Out {
    Folder,
    File,
    /// Writes into an input folder (`eval`) or only prints.
    None,
}

/// A command's arguments, given the path of every input (by name) and of the output.
type ArgsOf = dyn Fn(&dyn Fn(&str) -> PathBuf, &Path) -> Vec<OsString>;

struct Cmd {
    name: &'static str,
    inputs: Vec<Input>,
    out: Out,
    /// The arguments, given the path of every input (by name) and of the output.
    args: Box<ArgsOf>,
    /// Exit code of an error.
    code: i32,
}

fn os(parts: &[&dyn AsRef<std::ffi::OsStr>]) -> Vec<OsString> {
    parts.iter().map(|p| p.as_ref().to_os_string()).collect()
}

/// One bad variant of one file: its bytes (`None`: the file is removed) and a label.
fn variants(
    kind: Kind,
    valid: &[u8],
    png: &[u8],
    exr_small: &[u8],
) -> Vec<(String, Option<Vec<u8>>)> {
    let mut v: Vec<(String, Option<Vec<u8>>)> = vec![
        ("missing".into(), None),
        ("empty".into(), Some(vec![])),
        ("truncated".into(), Some(valid[..valid.len() / 2].to_vec())),
    ];
    let wrong_kind = match kind {
        Kind::Png | Kind::Exr => b"{\"vertices\": []}".to_vec(),
        _ => png.to_vec(),
    };
    v.push(("wrong kind".into(), Some(wrong_kind)));
    match kind {
        Kind::Cameras => {
            let text = String::from_utf8(valid.to_vec()).unwrap();
            let inf = replace_first_number_after(&text, "\"position\"", "1e999");
            v.push((
                "position out of range (1e999)".into(),
                Some(inf.into_bytes()),
            ));
            let fx0 = replace_first_number_after(&text, "\"fx\"", "0");
            v.push(("fx = 0".into(), Some(fx0.into_bytes())));
        }
        Kind::Ply => {
            let at = valid
                .windows(11)
                .position(|w| w == b"end_header\n")
                .unwrap()
                + 11;
            let mut b = valid.to_vec();
            b[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
            v.push(("NaN x".into(), Some(b)));
        }
        Kind::Png => v.push(("3x3".into(), Some(png.to_vec()))),
        // A non-finite depth is documented as unknown (SPEC.md §18, §19), not an error.
        Kind::Exr => v.push(("3x3".into(), Some(exr_small.to_vec()))),
        Kind::Json | Kind::Dir => {}
    }
    v
}

/// `text` with the first number after `key` replaced by `by`.
fn replace_first_number_after(text: &str, key: &str, by: &str) -> String {
    let k = text.find(key).unwrap_or_else(|| panic!("no {key}")) + key.len();
    let start = k + text[k..]
        .find(|c: char| c == '-' || c.is_ascii_digit())
        .unwrap();
    let end = start
        + text[start..]
            .find(|c: char| !(c.is_ascii_digit() || "-+.eE".contains(c)))
            .unwrap();
    format!("{}{by}{}", &text[..start], &text[end..])
}

/// Copy `from` into `to`, files hard-linked (spoiled files are replaced, never written in
/// place, so the originals are safe).
fn link_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let (src, dst) = (e.path(), to.join(e.file_name()));
        if src.is_dir() {
            link_tree(&src, &dst);
        } else if std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst).unwrap();
        }
    }
}

/// Replace (not overwrite) `p` with `bytes`, or remove it.
fn spoil(p: &Path, bytes: &Option<Vec<u8>>) {
    let _ = std::fs::remove_file(p);
    if let Some(b) = bytes {
        std::fs::write(p, b).unwrap();
    }
}

/// Every `.tmp` file under `dir`.
fn temporaries(dir: &Path) -> Vec<PathBuf> {
    let mut found = vec![];
    let Ok(entries) = std::fs::read_dir(dir) else {
        return found;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            found.extend(temporaries(&p));
        } else if p.to_string_lossy().contains(".tmp") {
            found.push(p);
        }
    }
    found
}

/// Run one case and check the contract; returns a description of what broke, if anything.
fn check(
    cmd: &Cmd,
    args: Vec<OsString>,
    names: &[String],
    out: &Path,
    out_before: Option<&[u8]>,
    case_dir: &Path,
    label: &str,
) -> Option<String> {
    let o = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .args(&args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let what = format!("{} [{label}]", cmd.name);
    if o.status.code() != Some(cmd.code) {
        return Some(format!("{what}: exit {:?}, stderr: {err}", o.status.code()));
    }
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    if lines.len() != 1 || err.contains("panicked") {
        return Some(format!("{what}: not one error line: {err}"));
    }
    if !names.iter().all(|n| lines[0].contains(n.as_str())) {
        return Some(format!(
            "{what}: the error does not name {names:?}: {}",
            lines[0]
        ));
    }
    match out_before {
        Some(b) => {
            if std::fs::read(out).ok().as_deref() != Some(b) {
                return Some(format!("{what}: the file at the output path changed"));
            }
        }
        None => {
            if out.exists() {
                return Some(format!("{what}: partial output at {}", out.display()));
            }
        }
    }
    let t = temporaries(case_dir);
    if !t.is_empty() {
        return Some(format!("{what}: temporaries left: {t:?}"));
    }
    None
}

#[test]
#[ignore = "slow tier (~30 s): cargo test -- --include-ignored"]
fn every_subcommand_answers_bad_input_with_one_error_line_and_no_output() {
    let tmp = TempDir::new("bad-input");
    let base = tmp.path();
    let demo = reference("demo");
    let lounge = reference("scenes/lounge");

    // Fixtures: a tiny trained run, a PNG and EXRs for the wrong-size and NaN variants.
    let run = base.join("fixture-run");
    let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .arg("train")
        .arg(&lounge)
        .arg("--out")
        .arg(&run)
        .args([
            "--iterations",
            "20",
            "--resolution",
            "4",
            "--sh-degree",
            "1",
        ])
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let small = unseen::io::image::ImageF32::new(3, 3, 3, vec![0.5; 27]).unwrap();
    let png_path = base.join("small.png");
    unseen::io::image::write_png(&png_path, &small).unwrap();
    let png = std::fs::read(&png_path).unwrap();
    let exr_small_path = base.join("small.exr");
    let gray = unseen::io::image::ImageF32::new(3, 3, 1, vec![1.0; 9]).unwrap();
    unseen::io::image::write_exr(&exr_small_path, &gray).unwrap();
    let exr_small = std::fs::read(&exr_small_path).unwrap();
    let cube = base.join("cube.json");
    let v: Vec<[f64; 3]> = (0..8)
        .map(|k| [(k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64])
        .collect();
    std::fs::write(&cube, serde_json::json!({ "vertices": v }).to_string()).unwrap();
    let ranges = base.join("ranges.json");
    std::fs::write(&ranges, r#"{"heldout_000": [1.0, 3.0]}"#).unwrap();
    let masks = base.join("masks");
    std::fs::create_dir_all(&masks).unwrap();
    let m = unseen::io::image::ImageF32::new(
        160,
        120,
        1,
        (0..160 * 120)
            .map(|i| ((i % 160) > 80) as u8 as f32)
            .collect(),
    )
    .unwrap();
    unseen::io::image::write_png(&masks.join("heldout_000.png"), &m).unwrap();
    let ex = base.join("fixture-extrapolate");
    let st = Command::new(env!("CARGO_BIN_EXE_unseen"))
        .arg("extrapolate")
        .arg(&run)
        .arg("--views")
        .arg(lounge.join("candidates.json"))
        .arg("--dataset")
        .arg(&lounge)
        .args(["--until", "views", "--out"])
        .arg(&ex)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let target = base.join("target.png");
    let grey = unseen::io::image::ImageF32::new(320, 240, 3, vec![0.5; 320 * 240 * 3]).unwrap();
    unseen::io::image::write_png(&target, &grey).unwrap();
    let train_config = base.join("train-config.json");
    std::fs::write(&train_config, r#"{"sh_increase_interval": 1}"#).unwrap();
    let pipeline_config = base.join("pipeline-config.json");
    std::fs::write(
        &pipeline_config,
        r#"{"qa_iterations": 2, "video_frames": 2,
            "stage1": {"iterations": 2, "densify": null},
            "stage2": {"iterations": 2, "densify": null},
            "interpolate": {"iterations": 2, "densify": null}}"#,
    )
    .unwrap();
    let dataset_files = vec![
        ("cameras.json", Kind::Cameras),
        ("split.json", Kind::Json),
        ("points3D.ply", Kind::Ply),
        ("images/train_000.png", Kind::Png),
    ];
    // The files of a run each command reads.
    const PLY: &str = "point_cloud/iteration_20/point_cloud.ply";
    let eval_files = vec![("config.json", Kind::Json), (PLY, Kind::Ply)];
    let qa_files = vec![
        ("cameras.json", Kind::Cameras),
        ("manifest.json", Kind::Json),
        (PLY, Kind::Ply),
    ];
    let extrapolate_files = vec![
        ("config.json", Kind::Json),
        ("manifest.json", Kind::Json),
        (PLY, Kind::Ply),
    ];

    let cmds: Vec<Cmd> = vec![
        Cmd {
            name: "render",
            inputs: vec![
                input("scene", demo.join("scene.ply"), Kind::Ply),
                input("cameras", demo.join("cameras.json"), Kind::Cameras),
            ],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"render",
                    &p("scene"),
                    &"--cameras",
                    &p("cameras"),
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "oracle forward",
            inputs: vec![
                input("scene", demo.join("scene.ply"), Kind::Ply),
                input("cameras", demo.join("cameras.json"), Kind::Cameras),
            ],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"oracle",
                    &"forward",
                    &"--scene",
                    &p("scene"),
                    &"--cameras",
                    &p("cameras"),
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "warp",
            inputs: vec![
                input("image", lounge.join("images/heldout_025.png"), Kind::Png),
                input("depth", lounge.join("depth/heldout_025.exr"), Kind::Exr),
                input("cameras", lounge.join("cameras.json"), Kind::Cameras),
            ],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"warp",
                    &"--image",
                    &p("image"),
                    &"--depth",
                    &p("depth"),
                    &"--from",
                    &"heldout_025",
                    &"--to",
                    &"heldout_033",
                    &"--cameras",
                    &p("cameras"),
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "collide",
            inputs: vec![
                input("a", cube.clone(), Kind::Json),
                input("b", cube.clone(), Kind::Json),
            ],
            out: Out::None,
            args: Box::new(|p, _| os(&[&"collide", &p("a"), &p("b")])),
            code: 1,
        },
        Cmd {
            name: "views",
            inputs: vec![
                input("cameras", lounge.join("cameras.json"), Kind::Cameras),
                input("ranges", ranges.clone(), Kind::Json),
                Input {
                    name: "masks",
                    path: masks.clone(),
                    kind: Kind::Dir,
                    inner: vec![("heldout_000.png", Kind::Png)],
                },
            ],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"views",
                    &"--cameras",
                    &p("cameras"),
                    &"--candidates",
                    &"heldout_000",
                    &"--masks",
                    &p("masks"),
                    &"--depth-ranges",
                    &p("ranges"),
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "oracle collide",
            inputs: vec![
                input("a", cube.clone(), Kind::Json),
                input("b", cube.clone(), Kind::Json),
            ],
            out: Out::Folder,
            args: Box::new(|p, out| os(&[&"oracle", &"collide", &p("a"), &p("b"), &"--out", &out])),
            code: 1,
        },
        Cmd {
            name: "oracle views",
            inputs: vec![
                input("cameras", lounge.join("cameras.json"), Kind::Cameras),
                input("ranges", ranges.clone(), Kind::Json),
                Input {
                    name: "masks",
                    path: masks.clone(),
                    kind: Kind::Dir,
                    inner: vec![("heldout_000.png", Kind::Png)],
                },
            ],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"oracle",
                    &"views",
                    &"--cameras",
                    &p("cameras"),
                    &"--candidates",
                    &"heldout_000",
                    &"--masks",
                    &p("masks"),
                    &"--depth-ranges",
                    &p("ranges"),
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "inpaint",
            inputs: vec![
                input("image", lounge.join("images/heldout_000.png"), Kind::Png),
                input("mask", masks.join("heldout_000.png"), Kind::Png),
            ],
            out: Out::File,
            args: Box::new(|p, out| os(&[&"inpaint", &p("image"), &p("mask"), &"--out", &out])),
            code: 1,
        },
        Cmd {
            name: "depth",
            inputs: vec![
                input("image", lounge.join("images/heldout_025.png"), Kind::Png),
                input("hint", lounge.join("depth/heldout_025.exr"), Kind::Exr),
            ],
            out: Out::File,
            args: Box::new(|p, out| {
                os(&[&"depth", &p("image"), &"--hint", &p("hint"), &"--out", &out])
            }),
            code: 1,
        },
        Cmd {
            name: "train",
            inputs: vec![
                Input {
                    name: "dataset",
                    path: lounge.clone(),
                    kind: Kind::Dir,
                    inner: dataset_files.clone(),
                },
                input("config", train_config.clone(), Kind::Json),
            ],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"train",
                    &p("dataset"),
                    &"--out",
                    &out,
                    &"--iterations",
                    &"2",
                    &"--resolution",
                    &"4",
                    &"--config",
                    &p("config"),
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "eval",
            inputs: vec![Input {
                name: "run",
                path: run.clone(),
                kind: Kind::Dir,
                inner: eval_files.clone(),
            }],
            out: Out::None,
            args: Box::new(|p, _| {
                os(&[
                    &"eval",
                    &p("run"),
                    &"--dataset",
                    &reference("scenes/lounge"),
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "qa-mask",
            inputs: vec![Input {
                name: "run",
                path: run.clone(),
                kind: Kind::Dir,
                inner: qa_files.clone(),
            }],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"qa-mask",
                    &p("run"),
                    &"--out",
                    &out,
                    &"--iterations",
                    &"2",
                    &"--sh-degree",
                    &"1",
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "compare",
            inputs: vec![
                Input {
                    name: "a",
                    path: ex.clone(),
                    kind: Kind::Dir,
                    inner: vec![("views/manifest.json", Kind::Json)],
                },
                input("b", ex.clone(), Kind::Dir),
            ],
            out: Out::None,
            args: Box::new(|p, _| os(&[&"compare", &p("a"), &p("b")])),
            code: 2,
        },
        Cmd {
            name: "extrapolate",
            inputs: vec![
                Input {
                    name: "run",
                    path: run.clone(),
                    kind: Kind::Dir,
                    inner: extrapolate_files.clone(),
                },
                input("views", lounge.join("candidates.json"), Kind::Cameras),
            ],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"extrapolate",
                    &p("run"),
                    &"--views",
                    &p("views"),
                    &"--dataset",
                    &reference("scenes/lounge"),
                    &"--until",
                    &"views",
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "oracle backward",
            inputs: vec![
                input("scene", demo.join("scene.ply"), Kind::Ply),
                input("cameras", demo.join("cameras.json"), Kind::Cameras),
                input("target", target.clone(), Kind::Png),
            ],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"oracle",
                    &"backward",
                    &"--scene",
                    &p("scene"),
                    &"--cameras",
                    &p("cameras"),
                    &"--target",
                    &p("target"),
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "mask-audit",
            inputs: vec![
                Input {
                    name: "run",
                    path: run.clone(),
                    kind: Kind::Dir,
                    inner: eval_files.clone(),
                },
                Input {
                    name: "dataset",
                    path: lounge.clone(),
                    kind: Kind::Dir,
                    inner: vec![("cameras.json", Kind::Cameras)],
                },
            ],
            out: Out::File,
            args: Box::new(|p, out| {
                os(&[
                    &"mask-audit",
                    &p("run"),
                    &"--dataset",
                    &p("dataset"),
                    &"--degrees",
                    &"1",
                    &"--iterations",
                    &"2",
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "audit",
            inputs: vec![Input {
                name: "dataset",
                path: lounge.clone(),
                kind: Kind::Dir,
                inner: vec![
                    ("candidates.json", Kind::Cameras),
                    ("evaluation.json", Kind::Cameras),
                    ("cameras.json", Kind::Cameras),
                ],
            }],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"audit",
                    &p("dataset"),
                    &"--out",
                    &out,
                    &"--train-iterations",
                    &"2",
                    &"--generators",
                    &"classical",
                    &"--variants",
                    &"full",
                    &"--only",
                    &"original/seed-0",
                ])
            }),
            code: 1,
        },
        Cmd {
            name: "audit-table",
            inputs: vec![Input {
                name: "audit",
                path: reference("audit/gallery-isolation"),
                kind: Kind::Dir,
                inner: vec![("audit.json", Kind::Json)],
            }],
            out: Out::None,
            args: Box::new(|p, _| os(&[&"audit-table", &p("audit")])),
            code: 1,
        },
        Cmd {
            name: "demo",
            inputs: vec![input("config", pipeline_config.clone(), Kind::Json)],
            out: Out::Folder,
            args: Box::new(|p, out| {
                os(&[
                    &"demo",
                    &"--iterations",
                    &"20",
                    &"--config",
                    &p("config"),
                    &"--out",
                    &out,
                ])
            }),
            code: 1,
        },
    ];

    let mut failures = vec![];
    let mut cases = 0;
    for (ci, cmd) in cmds.iter().enumerate() {
        // With every input valid the command succeeds (so each failure below is the
        // spoiled input's).
        let valid_out = base.join(format!("valid-{ci}"));
        std::fs::create_dir_all(&valid_out).unwrap();
        let path_of = |n: &str| {
            cmd.inputs
                .iter()
                .find(|i| i.name == n)
                .unwrap()
                .path
                .clone()
        };
        let o = Command::new(env!("CARGO_BIN_EXE_unseen"))
            .args((cmd.args)(&path_of, &valid_out.join("out")))
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{} with valid input: {}",
            cmd.name,
            String::from_utf8_lossy(&o.stderr)
        );
        let _ = std::fs::remove_dir_all(&valid_out);
        // Each input in turn is spoiled; the others stay valid.
        for (ii, inp) in cmd.inputs.iter().enumerate() {
            let mut targets: Vec<(PathBuf, Kind, bool)> = vec![(PathBuf::new(), inp.kind, false)];
            targets.extend(
                inp.inner
                    .iter()
                    .map(|(rel, k)| (PathBuf::from(rel), *k, true)),
            );
            for (rel, kind, inner) in targets {
                let valid = if inner {
                    std::fs::read(inp.path.join(&rel)).unwrap()
                } else if kind == Kind::Dir {
                    vec![]
                } else {
                    std::fs::read(&inp.path).unwrap()
                };
                let vs: Vec<(String, Option<Vec<u8>>)> = if kind == Kind::Dir {
                    vec![
                        ("missing".into(), None),
                        ("a file".into(), Some(b"not a folder".to_vec())),
                    ]
                } else {
                    variants(kind, &valid, &png, &exr_small)
                };
                for (vi, (label, bytes)) in vs.into_iter().enumerate() {
                    // Optional dataset files: without them INRIA's defaults apply.
                    let optional = ["split.json", "points3D.ply"];
                    if bytes.is_none() && inner && optional.contains(&rel.to_str().unwrap()) {
                        continue;
                    }
                    cases += 1;
                    let case_dir = base.join(format!(
                        "case-{ci}-{ii}-{}-{vi}",
                        rel.display().to_string().replace('/', "_")
                    ));
                    std::fs::create_dir_all(&case_dir).unwrap();
                    // The spoiled input lives in the case folder (a folder input is linked).
                    let ext = inp
                        .path
                        .extension()
                        .map(|e| format!(".{}", e.to_string_lossy()))
                        .unwrap_or_default();
                    let spoiled = case_dir.join(format!("{}{ext}", inp.name));
                    // The error names the spoiled file; a missing file inside a folder
                    // may instead be named by the folder and the file's name.
                    let names = if inner {
                        link_tree(&inp.path, &spoiled);
                        let f = spoiled.join(&rel);
                        spoil(&f, &bytes);
                        if bytes.is_none() {
                            let file = rel.file_name().unwrap().to_string_lossy().into_owned();
                            vec![spoiled.display().to_string(), file]
                        } else {
                            vec![f.display().to_string()]
                        }
                    } else {
                        spoil(&spoiled, &bytes);
                        vec![spoiled.display().to_string()]
                    };
                    let path_of = |n: &str| -> PathBuf {
                        if n == inp.name {
                            spoiled.clone()
                        } else {
                            cmd.inputs
                                .iter()
                                .find(|i| i.name == n)
                                .unwrap()
                                .path
                                .clone()
                        }
                    };
                    let out = case_dir.join("out");
                    let args = (cmd.args)(&path_of, &out);
                    let label = format!("{} {}: {label}", inp.name, rel.display());
                    if let Some(f) = check(cmd, args, &names, &out, None, &case_dir, &label) {
                        failures.push(f);
                    }
                    let _ = std::fs::remove_dir_all(&case_dir);
                }
            }
        }
        // Output paths: an existing file where a folder goes; a folder that cannot be
        // created (its parent is a file).
        if cmd.out == Out::None {
            continue;
        }
        let case_dir = base.join(format!("case-{ci}-out"));
        std::fs::create_dir_all(&case_dir).unwrap();
        let path_of = |n: &str| {
            cmd.inputs
                .iter()
                .find(|i| i.name == n)
                .unwrap()
                .path
                .clone()
        };
        if cmd.out == Out::Folder {
            cases += 1;
            let out = case_dir.join("out");
            std::fs::write(&out, b"keep").unwrap();
            let args = (cmd.args)(&path_of, &out);
            if let Some(f) = check(
                cmd,
                args,
                &[out.display().to_string()],
                &out,
                Some(b"keep"),
                &case_dir,
                "out is a file",
            ) {
                failures.push(f);
            }
        }
        cases += 1;
        let blocker = case_dir.join("blocker");
        std::fs::write(&blocker, b"file").unwrap();
        let out = blocker.join("out");
        let args = (cmd.args)(&path_of, &out);
        if let Some(f) = check(
            cmd,
            args,
            &[blocker.display().to_string()],
            &out,
            None,
            &case_dir,
            "out under a file",
        ) {
            failures.push(f);
        }
        let _ = std::fs::remove_dir_all(&case_dir);
    }
    assert!(
        failures.is_empty(),
        "{} of {cases} bad-input cases broke the contract:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
