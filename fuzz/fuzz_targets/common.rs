//! Shared by the targets that exercise path-based readers: the input bytes are written to
//! a file in this process's scratch folder (libFuzzer runs one input at a time).
#![allow(dead_code)]
use std::path::PathBuf;

/// `<temp>/unseen-fuzz-<pid>/<name>` holding `data`.
pub fn file_with(name: &str, data: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("unseen-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, data).unwrap();
    p
}

/// The scene of the float targets (`raster`, `backward`): bytes 0 and 1 give the image
/// size (1 to `max_side`), bytes from 4 on are f32s of any bit pattern, 23 per Gaussian at
/// SH degree 1; the camera is rotated, so that huge means can overflow in camera space.
/// Also returns the floats. `None` for inputs shorter than 4 bytes.
pub fn float_scene(
    data: &[u8],
    max_side: u32,
) -> Option<(unseen::camera::Camera, unseen::gaussian::Gaussians, Vec<f32>)> {
    if data.len() < 4 {
        return None;
    }
    let w = 1 + (data[0] as u32 % max_side);
    let h = 1 + (data[1] as u32 % max_side);
    let floats: Vec<f32> = data[4..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let mut g = unseen::gaussian::Gaussians::new(1).unwrap();
    for p in floats.chunks_exact(23) {
        g.push([p[0], p[1], p[2]], [p[3], p[4], p[5]], [p[6], p[7], p[8], p[9]], p[10],
               [p[11], p[12], p[13]], &p[14..23]);
    }
    let cam = unseen::camera::Camera::look_at("fuzz", w, h, 1.0, [0.1, 0.2, -0.3].into(),
        [0.0, 0.0, 3.0].into(), [0.2, -1.0, 0.0].into()).unwrap();
    Some((cam, g, floats))
}
