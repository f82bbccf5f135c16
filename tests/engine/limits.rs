//! Resource limits (SPEC.md §3, §10): files that declare absurd sizes are refused with an
//! error naming the file before anything of the declared size is allocated. Each case
//! declares ≥ 10¹² elements in a file of a few hundred bytes; an attempt to allocate them
//! would abort the test process, so passing at all is half the check.
use crate::support::TempDir;
use std::path::{Path, PathBuf};

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// `r` is an error naming `path` and saying `why`.
fn assert_refused<T>(r: unseen::error::Result<T>, path: &Path, why: &str) {
    let e = match r {
        Ok(_) => panic!("{}: accepted", path.display()),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains(&path.display().to_string()) && e.contains(why),
        "expected an error naming the file and saying '{why}': {e}"
    );
}

#[test]
fn a_ply_declaring_10_to_the_12_vertices_is_refused() {
    let dir = TempDir::new("limits-ply");
    let props: String = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity"]
        .iter()
        .chain(&[
            "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ])
        .map(|n| format!("property float {n}\n"))
        .collect();
    for format in ["binary_little_endian", "ascii"] {
        let header =
            format!("ply\nformat {format} 1.0\nelement vertex 1000000000000\n{props}end_header\n");
        let mut bytes = header.into_bytes();
        bytes.extend_from_slice(&[0u8; 56]);
        let p = write(dir.path(), &format!("{format}.ply"), &bytes);
        let r = unseen::gaussian::ply::read_ply(&p);
        assert_refused(r, &p, "1000000000000 vertex rows need at least");
    }
}

#[test]
fn colmap_files_with_absurd_counts_are_refused() {
    let dir = TempDir::new("limits-colmap");
    let sparse = dir.path().join("sparse/0");
    std::fs::create_dir_all(&sparse).unwrap();
    write(&sparse, "images.bin", &0u64.to_le_bytes());
    write(&sparse, "points3D.bin", &0u64.to_le_bytes());
    // cameras.bin declaring 2^60 cameras, then one SIMPLE_PINHOLE camera.
    let mut cams = (1u64 << 60).to_le_bytes().to_vec();
    cams.extend_from_slice(&1u32.to_le_bytes());
    cams.extend_from_slice(&0i32.to_le_bytes());
    cams.extend_from_slice(&64u64.to_le_bytes());
    cams.extend_from_slice(&48u64.to_le_bytes());
    for v in [50.0f64, 32.0, 24.0] {
        cams.extend_from_slice(&v.to_le_bytes());
    }
    let p = write(&sparse, "cameras.bin", &cams);
    assert_refused(
        unseen::camera::colmap::read_colmap_model(&sparse),
        &p,
        "exceeds the file size",
    );
    // A valid cameras.bin, images.bin declaring 10^12 images.
    cams[..8].copy_from_slice(&1u64.to_le_bytes());
    write(&sparse, "cameras.bin", &cams);
    let mut images = 1_000_000_000_000u64.to_le_bytes().to_vec();
    images.extend_from_slice(&[0u8; 80]);
    let p = write(&sparse, "images.bin", &images);
    assert_refused(
        unseen::camera::colmap::read_colmap_model(&sparse),
        &p,
        "exceeds the file size",
    );
    // points3D.bin declaring 10^12 points.
    write(&sparse, "images.bin", &0u64.to_le_bytes());
    let mut points = 1_000_000_000_000u64.to_le_bytes().to_vec();
    points.extend_from_slice(&[0u8; 43]);
    let p = write(&sparse, "points3D.bin", &points);
    assert_refused(
        unseen::camera::colmap::read_colmap_model(&sparse),
        &p,
        "exceeds the file size",
    );
}

/// CRC-32 (ISO-HDLC) for the PNG chunks below.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn png_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let mut body = kind.to_vec();
    body.extend_from_slice(data);
    out.extend_from_slice(&body);
    out.extend_from_slice(&crc32(&body).to_be_bytes());
}

#[test]
fn images_declaring_10_to_the_12_pixels_are_refused() {
    let dir = TempDir::new("limits-images");
    // PNG: IHDR 10^6 × 10^6, 8-bit RGB, a tiny IDAT.
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = 1_000_000u32.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&1_000_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    png_chunk(&mut png, b"IHDR", &ihdr);
    png_chunk(
        &mut png,
        b"IDAT",
        &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    );
    png_chunk(&mut png, b"IEND", &[]);
    let p = write(dir.path(), "huge.png", &png);
    assert_refused(unseen::io::image::read_png(&p), &p, "Memory limit exceeded");
    assert_refused(
        unseen::io::image::read_rgb(&p, [0.0; 3]),
        &p,
        "Memory limit exceeded",
    );

    // EXR: a valid 4×2 file whose data window is rewritten to 10^6 × 10^6.
    let small = dir.path().join("small.exr");
    let img = unseen::io::image::ImageF32::new(4, 2, 1, vec![0.5; 8]).unwrap();
    unseen::io::image::write_exr(&small, &img).unwrap();
    let mut bytes = std::fs::read(&small).unwrap();
    let key = b"dataWindow\0box2i\0";
    let at = bytes
        .windows(key.len())
        .position(|w| w == key)
        .expect("dataWindow attribute")
        + key.len()
        + 4;
    bytes[at + 8..at + 12].copy_from_slice(&999_999i32.to_le_bytes());
    bytes[at + 12..at + 16].copy_from_slice(&999_999i32.to_le_bytes());
    let p = write(dir.path(), "huge.exr", &bytes);
    assert_refused(
        unseen::io::image::read_exr(&p, &["Y"]),
        &p,
        "the header declares 1000000x1000000 pixels",
    );
}

#[test]
fn an_npy_whose_shape_overflows_is_refused() {
    let dir = TempDir::new("limits-npy");
    for (shape, why) in [
        ("(4611686018427387904, 4)", "the shape's size overflows"),
        ("(1000000000000, 3)", "data size does not match the shape"),
    ] {
        let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend_from_slice(&(header.len() as u16).to_le_bytes());
        b.extend_from_slice(header.as_bytes());
        let p = write(dir.path(), "huge.npy", &b);
        assert_refused(unseen::io::npy::read_npy_f32(&p), &p, why);
    }
}
