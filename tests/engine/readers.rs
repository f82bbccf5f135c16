//! Readers and writers: COLMAP (against files COLMAP wrote), cameras.json, transforms.json,
//! INRIA PLY (round trip, ASCII, big-endian, malformed input).
use crate::support::{TempDir, reference};
use glam::{DMat3, DVec3};
use std::path::Path;
use unseen::camera::colmap::read_colmap_model;
use unseen::camera::inria::{cameras_json_string, read_cameras_json};
use unseen::camera::transforms::read_transforms_json;
use unseen::error::ErrorKind;
use unseen::gaussian::ply::{parse_ply, ply_bytes, read_ply, write_ply};
use unseen::scene::random_scene;

/// A fresh folder, removed when the guard drops.
fn temp_dir(name: &str) -> TempDir {
    TempDir::new(&format!("readers-{name}"))
}

fn mat_from_rows(v: &serde_json::Value) -> DMat3 {
    let r = |i: usize, j: usize| v[i][j].as_f64().unwrap();
    DMat3::from_cols(
        DVec3::new(r(0, 0), r(1, 0), r(2, 0)),
        DVec3::new(r(0, 1), r(1, 1), r(2, 1)),
        DVec3::new(r(0, 2), r(1, 2), r(2, 2)),
    )
}

#[test]
fn colmap_text_and_binary_match_pycolmap() {
    let dir = reference("colmap/pinhole");
    let exp: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("expected.json")).unwrap()).unwrap();
    for sub in ["sparse_txt", "sparse_bin"] {
        let model = read_colmap_model(&dir.join(sub)).unwrap();
        let cams = exp["cameras"].as_array().unwrap();
        assert_eq!(model.cameras.len(), cams.len(), "{sub}");
        for (c, e) in model.cameras.iter().zip(cams) {
            assert_eq!(c.name, e["name"].as_str().unwrap());
            assert_eq!(c.width as u64, e["width"].as_u64().unwrap());
            assert_eq!(c.height as u64, e["height"].as_u64().unwrap());
            // Text files print 17 significant digits, so intrinsics round-trip exactly.
            for (got, key) in [(c.fx, "fx"), (c.fy, "fy"), (c.cx, "cx"), (c.cy, "cy")] {
                assert_eq!(got, e[key].as_f64().unwrap(), "{sub} {key}");
            }
            let r = mat_from_rows(&e["world_from_camera"]);
            assert!(
                (c.world_from_camera_rotation - r).abs_diff_eq(DMat3::ZERO, 1e-14),
                "{sub}"
            );
            let centre = DVec3::new(
                e["center"][0].as_f64().unwrap(),
                e["center"][1].as_f64().unwrap(),
                e["center"][2].as_f64().unwrap(),
            );
            assert!(
                (c.center - centre).length() < 1e-13,
                "{sub}: {} vs {}",
                c.center,
                centre
            );
        }
        let pts = exp["points"].as_array().unwrap();
        assert_eq!(model.points.len(), pts.len());
        for (p, e) in model.points.iter().zip(pts) {
            for k in 0..3 {
                assert_eq!(p.xyz[k], e["xyz"][k].as_f64().unwrap());
                assert_eq!(p.rgb[k] as u64, e["rgb"][k].as_u64().unwrap());
            }
        }
    }
}

#[test]
fn colmap_distorted_model_is_a_clear_error() {
    for sub in ["sparse_txt", "sparse_bin"] {
        let err = read_colmap_model(&reference("colmap/distorted").join(sub)).unwrap_err();
        assert_eq!(err.kind, ErrorKind::Unsupported, "{sub}: {err}");
        assert!(
            err.to_string().contains("OPENCV") && err.to_string().contains("cameras."),
            "{err}"
        );
    }
    let err = read_colmap_model(Path::new("/nonexistent/sparse")).unwrap_err();
    assert_eq!(err.kind, ErrorKind::Io);
    assert!(
        err.to_string().contains("/nonexistent/sparse/cameras.txt"),
        "{err}"
    );
}

#[test]
fn colmap_binary_truncations_are_errors_not_panics() {
    let dir = reference("colmap/pinhole/sparse_bin");
    for file in ["cameras.bin", "images.bin", "points3D.bin"] {
        let full = std::fs::read(dir.join(file)).unwrap();
        let t = temp_dir(&format!("trunc-{file}"));
        for f in ["cameras.bin", "images.bin", "points3D.bin"] {
            std::fs::copy(dir.join(f), t.join(f)).unwrap();
        }
        for cut in [0, 1, 7, 8, 9, full.len() / 2, full.len() - 1] {
            std::fs::write(t.join(file), &full[..cut]).unwrap();
            let err = read_colmap_model(&t).unwrap_err();
            assert_eq!(err.kind, ErrorKind::Parse, "{file} cut at {cut}: {err}");
            assert!(err.to_string().contains(file), "{err}");
        }
    }
}

#[test]
fn cameras_json_round_trip() {
    let model = read_colmap_model(&reference("colmap/pinhole/sparse_bin")).unwrap();
    let d = temp_dir("cams");
    let p = d.join("cameras.json");
    std::fs::write(&p, cameras_json_string(&model.cameras)).unwrap();
    let back = read_cameras_json(&p).unwrap();
    assert_eq!(back, model.cameras);
    std::fs::write(&p, b"[{\"id\": 0}]").unwrap();
    let err = read_cameras_json(&p).unwrap_err();
    assert!(
        err.to_string().contains("cameras.json") && err.kind == ErrorKind::Parse,
        "{err}"
    );
}

#[test]
fn transforms_json_opengl_to_opencv() {
    let d = temp_dir("transforms");
    // nerfstudio style: intrinsics given; identity c2w looks down world -z with y up.
    let text = r#"{"fl_x": 100.0, "fl_y": 110.0, "cx": 40.0, "cy": 30.0, "w": 80, "h": 60,
        "frames": [{"file_path": "images/a.png",
                    "transform_matrix": [[1,0,0,1],[0,1,0,2],[0,0,1,3],[0,0,0,1]]}]}"#;
    std::fs::write(d.join("transforms.json"), text).unwrap();
    let cams = read_transforms_json(&d.join("transforms.json")).unwrap();
    let c = &cams[0];
    assert_eq!(
        (c.width, c.height, c.fx, c.fy, c.cx, c.cy),
        (80, 60, 100.0, 110.0, 40.0, 30.0)
    );
    assert_eq!(c.center, DVec3::new(1.0, 2.0, 3.0));
    assert_eq!(
        c.world_from_camera_rotation,
        DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0))
    );
    // A point in front of the camera (world -z) has positive camera z.
    assert!(c.camera_from_world_point(DVec3::new(1.0, 2.0, 0.0)).z > 0.0);
    // NeRF-synthetic style: camera_angle_x and the image size from the PNG header.
    std::fs::create_dir_all(d.join("train")).unwrap();
    image::RgbImage::new(40, 20)
        .save(d.join("train/r_0.png"))
        .unwrap();
    let text = r#"{"camera_angle_x": 0.6911112070083618,
        "frames": [{"file_path": "./train/r_0",
                    "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#;
    std::fs::write(d.join("transforms_train.json"), text).unwrap();
    let c = &read_transforms_json(&d.join("transforms_train.json")).unwrap()[0];
    assert_eq!((c.width, c.height), (40, 20));
    assert!((c.fx - 20.0 / (0.5f64 * 0.6911112070083618).tan()).abs() < 1e-12);
    // Missing image and no w/h: an error naming the image.
    let text = r#"{"camera_angle_x": 0.7, "frames": [{"file_path": "nope",
        "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#;
    std::fs::write(d.join("bad.json"), text).unwrap();
    let err = read_transforms_json(&d.join("bad.json")).unwrap_err();
    assert!(err.to_string().contains("nope"), "{err}");
}

#[test]
fn ply_round_trip_is_exact_for_every_degree() {
    let d = temp_dir("ply");
    for deg in 0..=5 {
        let g = random_scene(257, deg, deg as u64 + 100, 0.01, 0.5);
        let p = d.join(format!("deg{deg}.ply"));
        write_ply(&g, &p).unwrap();
        let (back, info) = read_ply(&p).unwrap();
        assert_eq!(back, g, "degree {deg}");
        assert!(info.ignored_properties.is_empty());
        let temporaries: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
            .collect();
        assert!(temporaries.is_empty(), "{temporaries:?}");
    }
}

/// The same Gaussians as ASCII, big-endian with doubles, and with extra properties and
/// elements, load to the same values.
#[test]
fn ply_ascii_big_endian_and_extra_properties() {
    let g = random_scene(5, 1, 9, 0.01, 0.5);
    let bin = ply_bytes(&g).unwrap();
    let (base, _) = parse_ply(&bin, Path::new("bin.ply")).unwrap();
    let header_end = bin.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = std::str::from_utf8(&bin[..header_end]).unwrap();
    let names: Vec<&str> = header
        .lines()
        .filter_map(|l| l.strip_prefix("property float "))
        .collect();
    let values: Vec<f32> = bin[header_end..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let nprop = names.len();

    // ASCII with an extra property "confidence" and a face element after the vertices.
    let mut ascii =
        String::from("ply\nformat ascii 1.0\ncomment made by a test\nelement vertex 5\n");
    for n in &names {
        ascii += &format!("property float {n}\n");
    }
    ascii += "property uchar confidence\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    for row in values.chunks_exact(nprop) {
        let vals: Vec<String> = row.iter().map(|v| format!("{v:?}")).collect();
        ascii += &format!("{} 7\n", vals.join(" "));
    }
    ascii += "3 0 1 2\n";
    let (a, info) = parse_ply(ascii.as_bytes(), Path::new("a.ply")).unwrap();
    assert_eq!(a, base);
    assert_eq!(info.ignored_properties, vec!["confidence".to_string()]);
    assert_eq!(info.ignored_elements, vec![("face".to_string(), 1)]);

    // Big-endian doubles, properties in reverse order.
    let mut be = String::from("ply\nformat binary_big_endian 1.0\nelement vertex 5\n");
    for n in names.iter().rev() {
        be += &format!("property double {n}\n");
    }
    be += "end_header\n";
    let mut bytes = be.into_bytes();
    for row in values.chunks_exact(nprop) {
        for v in row.iter().rev() {
            bytes.extend_from_slice(&(*v as f64).to_be_bytes());
        }
    }
    let (b, _) = parse_ply(&bytes, Path::new("be.ply")).unwrap();
    assert_eq!(b, base);
}

#[test]
fn malformed_ply_files_are_clear_errors() {
    let g = random_scene(3, 3, 1, 0.01, 0.5);
    let bin = ply_bytes(&g).unwrap();
    let p = Path::new("scene.ply");
    let check = |data: &[u8], needle: &str| {
        let err = parse_ply(data, p).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.starts_with("scene.ply: ") && msg.contains(needle),
            "{msg}"
        );
    };
    check(&bin[..bin.len() - 1], "truncated");
    check(b"hello", "not a PLY file");
    check(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n",
        "missing",
    );
    // Replace text in the header only, keeping the binary body intact.
    let edit = |from: &str, to: &str| {
        let end = bin.windows(10).position(|w| w == b"end_header").unwrap();
        let head = std::str::from_utf8(&bin[..end]).unwrap().replace(from, to);
        [head.as_bytes(), &bin[end..]].concat()
    };
    check(&edit("f_rest_44", "f_rest_99"), "SH degree");
    check(
        &edit("element vertex 3", "element vertex 99999999999"),
        "truncated",
    );
    check(
        &edit("binary_little_endian", "binary_middle_endian"),
        "unknown PLY format",
    );
    check(
        &edit(
            "property float opacity",
            "property float opacity\nproperty float opacity",
        ),
        "twice",
    );
    // Found by the `ply` fuzz target (2026-11-24): an f_rest index of usize::MAX overflowed
    // `k + 1` (a panic with overflow checks, a wrap without).
    let crash = b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float _dc_0\n\
        property float f_dc_\nproperty float f_rest_18446744073709551615 \t\t\n\
        end_headery f5 0.5\n";
    check(crash, "SH degree 5 has 105 f_rest fields");
    check(
        &edit("f_rest_44", "f_rest_105"),
        "SH degree 5 has 105 f_rest fields",
    );
    let err = read_ply(Path::new("/nonexistent/x.ply")).unwrap_err();
    assert_eq!(err.kind, ErrorKind::Io);
    assert!(err.to_string().contains("/nonexistent/x.ply"));
}

/// Point clouds: float or uchar colours, no colours, and clear errors for a missing
/// coordinate, a truncated body and a non-finite position.
#[test]
fn point_cloud_ply_reading() {
    use unseen::gaussian::ply::parse_point_cloud;
    let p = Path::new("points.ply");
    let ascii = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n\
1 2 3 255 0 51\n-1 0.5 2 0 255 0\n";
    let pc = parse_point_cloud(ascii, p).unwrap();
    assert_eq!(pc.xyz, vec![[1.0, 2.0, 3.0], [-1.0, 0.5, 2.0]]);
    assert_eq!(pc.rgb[0], [1.0, 0.0, 0.2]);
    let no_colour =
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\n\
property double z\nend_header\n1 2 3\n";
    assert_eq!(parse_point_cloud(no_colour, p).unwrap().rgb, vec![[0.5; 3]]);
    let no_z = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n";
    let e = parse_point_cloud(no_z, p).unwrap_err().to_string();
    assert!(
        e.contains("points.ply") && e.contains("'z' is missing"),
        "{e}"
    );
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\n\
property float y\nproperty float z\nend_header\n"
        .to_vec();
    bin.extend_from_slice(&[0u8; 12]);
    let e = parse_point_cloud(&bin, p).unwrap_err().to_string();
    assert!(e.contains("truncated"), "{e}");
    let nan = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
property float z\nend_header\nnan 0 1\n";
    let e = parse_point_cloud(nan, p).unwrap_err().to_string();
    assert!(e.contains("non-finite"), "{e}");
}

/// A manifest listing a file outside its folder, and a `steps.json` naming a step outside
/// the run, are clear errors: readers join those paths to the folder and must not leave it.
#[test]
fn manifests_and_step_lists_stay_inside_their_folder() {
    use unseen::io::manifest::{FileEntry, Manifest};
    let t = temp_dir("inside");
    let dir = t.path().join("run");
    std::fs::create_dir_all(&dir).unwrap();
    for bad in ["../outside.txt", "/etc/hostname", "a/../../b", "./a", ""] {
        let m = Manifest::new(
            "train",
            "",
            serde_json::json!({}),
            vec![FileEntry::new(bad, b"x")],
        );
        std::fs::write(dir.join("manifest.json"), m.text()).unwrap();
        let e = Manifest::read(&dir).unwrap_err().to_string();
        assert!(
            e.contains("manifest.json") && e.contains("inside"),
            "{bad}: {e}"
        );
    }
    let good = Manifest::new(
        "train",
        "",
        serde_json::json!({}),
        vec![FileEntry::new("a/b.ply", b"x")],
    );
    std::fs::write(dir.join("manifest.json"), good.text()).unwrap();
    assert!(Manifest::read(&dir).is_ok());
    std::fs::write(dir.join("steps.json"), r#"["../run"]"#).unwrap();
    let e = unseen::pipeline::compare::compare(&dir, &dir, 0.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("steps.json") && e.contains("inside"), "{e}");
}

/// Found by the `run_readers` fuzz target (fuzz/README.md, Findings): a 752-byte EXR whose
/// header declares a PIZ-compressed layer large enough that the decoder asked for 772 MB
/// (within `read_exr`'s 1 GiB bound for compressions without a small ratio). `read_depth`
/// knows the size it wants and now refuses a header that declares another before
/// decoding: the error is the size mismatch, from the header alone.
#[test]
fn a_depth_header_of_another_size_is_refused_before_decoding() {
    let t = temp_dir("depth-header-size");
    for (name, bytes) in [
        (
            "piz-header",
            &include_bytes!("../../fuzz/regressions/run_readers-oom-piz-header")[..],
        ),
        (
            "rss",
            &include_bytes!("../../fuzz/regressions/run_readers-oom-rss")[..],
        ),
    ] {
        // The target's layout: bytes 0–1 give the size, the rest is the file.
        let (w, h) = (1 + bytes[0] as usize % 64, 1 + bytes[1] as usize % 64);
        let p = t.path().join(format!("{name}.depth.exr"));
        std::fs::write(&p, &bytes[2..]).unwrap();
        let e = unseen::io::image::read_depth(&p, w, h)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(&format!("but the image is {w}x{h}")) || e.contains("cannot read EXR"),
            "{name}: {e}"
        );
        assert!(e.contains(&*p.to_string_lossy()), "{name}: {e}");
    }
}

/// The rooms' truth depths decode to the bits OpenEXR decodes: every
/// `scenes/<room>/depth/*.exr` read by `read_depth` hashes (float32 little-endian,
/// row-major) to the line of `depth/decoded-sha256.txt`, which
/// `reference_data/generate/make_depth_manifest.py` wrote with OpenEXR 3.5.3 from the files
/// as Mitsuba wrote them (PIZ), before it re-wrote them as ZIP (17 % smaller). Bit for
/// bit: the re-encoding lost nothing, and our reader agrees with the format's own library
/// on both compressions' output.
#[test]
fn scene_depths_decode_to_the_bits_openexr_decodes() {
    for room in ["lounge", "gallery"] {
        let folder = reference(&format!("scenes/{room}/depth"));
        let manifest = std::fs::read_to_string(folder.join("decoded-sha256.txt")).unwrap();
        let mut files: Vec<String> = std::fs::read_dir(&folder)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".exr"))
            .collect();
        files.sort();
        let listed: Vec<(&str, &str)> = manifest
            .lines()
            .map(|l| l.split_once("  ").expect("<sha256>  <name>"))
            .collect();
        assert_eq!(
            listed
                .iter()
                .map(|(_, n)| n.to_string())
                .collect::<Vec<_>>(),
            files,
            "{room}: the manifest lists every depth"
        );
        for (sha, name) in listed {
            let depth = unseen::io::image::read_depth(&folder.join(name), 160, 120).unwrap();
            let bytes: Vec<u8> = depth.iter().flat_map(|z| z.to_le_bytes()).collect();
            assert_eq!(unseen::io::sha256_hex(&bytes), sha, "{room}/{name}");
        }
    }
}
