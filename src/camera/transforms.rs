//! nerfstudio / NeRF-synthetic `transforms.json`.
//!
//! Each frame has `file_path` and a 4×4 `transform_matrix`, the camera-to-world matrix in the
//! OpenGL / Blender camera frame (+x right, +y up, +z backward); we convert it with
//! [`super::CV_FROM_OPENGL`]. Intrinsics: nerfstudio's `fl_x`, `fl_y`, `cx`, `cy`, `w`, `h`
//! (top level or per frame), or NeRF-synthetic's `camera_angle_x` with the image size read
//! from the image file's header (`file_path`, `.png` appended when it has no extension).

use super::{CV_FROM_OPENGL, Camera, read_file};
use crate::error::{Error, Result};
use glam::{DMat3, DVec3};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn num(v: &Value, key: &str) -> Option<f64> {
    v.get(key).and_then(Value::as_f64)
}

/// Read `transforms.json`; image paths are resolved relative to its folder.
pub fn read_transforms_json(path: &Path) -> Result<Vec<Camera>> {
    let text = read_file(path)?;
    let root: Value = serde_json::from_slice(&text)
        .map_err(|e| Error::parse(path, format!("invalid JSON: {e}")))?;
    let frames = root
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| Error::parse(path, "no \"frames\" list"))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut cams = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let err = |m: String| Error::parse(path, format!("frame {i}: {m}"));
        let file = f
            .get("file_path")
            .and_then(Value::as_str)
            .ok_or_else(|| err("no \"file_path\"".into()))?;
        let m = f
            .get("transform_matrix")
            .and_then(Value::as_array)
            .filter(|rows| rows.len() >= 3)
            .ok_or_else(|| err("no 4x4 \"transform_matrix\"".into()))?;
        let mut a = [[0.0f64; 4]; 3];
        for (r, row) in m.iter().take(3).enumerate() {
            let row = row.as_array().filter(|r| r.len() == 4);
            let row = row.ok_or_else(|| err("transform_matrix rows must have 4 numbers".into()))?;
            for (c, v) in row.iter().enumerate() {
                a[r][c] = v
                    .as_f64()
                    .ok_or_else(|| err("non-numeric matrix entry".into()))?;
            }
        }
        let world_from_gl = DMat3::from_cols(
            DVec3::new(a[0][0], a[1][0], a[2][0]),
            DVec3::new(a[0][1], a[1][1], a[2][1]),
            DVec3::new(a[0][2], a[1][2], a[2][2]),
        );
        let center = DVec3::new(a[0][3], a[1][3], a[2][3]);
        let get = |k: &str| num(f, k).or_else(|| num(&root, k));
        let (w, h) = match (get("w"), get("h")) {
            (Some(w), Some(h)) => (w as u32, h as u32),
            _ => image_size(&frame_image_path(dir, file)).map_err(|e| e.at(path))?,
        };
        let (fx, fy) = match (get("fl_x"), get("fl_y"), get("camera_angle_x")) {
            (Some(fx), fy, _) => (fx, fy.unwrap_or(fx)),
            (None, _, Some(ax)) => {
                let fx = 0.5 * w as f64 / (0.5 * ax).tan();
                (fx, fx)
            }
            _ => return Err(err("no focal length (fl_x or camera_angle_x)".into())),
        };
        let mut cam = Camera::new(file, w, h, fx, fy, world_from_gl * CV_FROM_OPENGL, center)
            .map_err(|e| e.at(path))?;
        if let Some(cx) = get("cx") {
            cam.cx = cx;
        }
        if let Some(cy) = get("cy") {
            cam.cy = cy;
        }
        cam.validate().map_err(|e| e.at(path))?;
        cams.push(cam);
    }
    Ok(cams)
}

/// The image file of a frame's `file_path` (relative to the JSON's folder): as written when
/// it has an extension, else with `.png` appended (NeRF-synthetic), else as written.
pub fn frame_image_path(dir: &Path, file_path: &str) -> PathBuf {
    let file = dir.join(file_path);
    if file.extension().is_some() || !file.with_extension("png").exists() {
        file
    } else {
        file.with_extension("png")
    }
}

fn image_size(file: &Path) -> Result<(u32, u32)> {
    if file.exists() {
        return image::image_dimensions(file)
            .map_err(|e| Error::parse(file, format!("cannot read image size: {e}")));
    }
    Err(Error::invalid(format!(
        "no w/h in transforms.json and image {} not found",
        file.display()
    )))
}
