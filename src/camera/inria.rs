//! INRIA 3DGS `cameras.json`: a list of
//! `{id, img_name, width, height, position: [3], rotation: [[3];3], fx, fy}`.
//!
//! INRIA's `camera_to_JSON` inverts the world-to-camera matrix, so `rotation` (rows) and
//! `position` are the rotation and translation of `world_from_camera` in the OpenCV camera
//! frame. The principal point is the image centre unless the optional `cx`, `cy` (our
//! extension, written only when off-centre) are present.

use super::{Camera, read_file};
use crate::error::{Error, Result};
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Serialize, Deserialize)]
struct Entry {
    id: i64,
    img_name: String,
    width: u32,
    height: u32,
    position: [f64; 3],
    rotation: [[f64; 3]; 3],
    fx: f64,
    fy: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cx: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cy: Option<f64>,
}

/// Parse INRIA `cameras.json` text; `path` is used only in error messages.
pub fn parse_cameras_json(text: &[u8], path: &Path) -> Result<Vec<Camera>> {
    let entries: Vec<Entry> = serde_json::from_slice(text)
        .map_err(|e| Error::parse(path, format!("not an INRIA cameras.json list: {e}")))?;
    let mut cams = Vec::with_capacity(entries.len());
    for e in entries {
        let r = e.rotation;
        let rot = DMat3::from_cols(
            DVec3::new(r[0][0], r[1][0], r[2][0]),
            DVec3::new(r[0][1], r[1][1], r[2][1]),
            DVec3::new(r[0][2], r[1][2], r[2][2]),
        );
        let mut cam = Camera::new(
            e.img_name,
            e.width,
            e.height,
            e.fx,
            e.fy,
            rot,
            DVec3::from_array(e.position),
        )
        .map_err(|err| err.at(path))?;
        if let Some(cx) = e.cx {
            cam.cx = cx;
        }
        if let Some(cy) = e.cy {
            cam.cy = cy;
        }
        cam.validate().map_err(|err| err.at(path))?;
        cams.push(cam);
    }
    Ok(cams)
}

/// Read INRIA `cameras.json`.
pub fn read_cameras_json(path: &Path) -> Result<Vec<Camera>> {
    parse_cameras_json(&read_file(path)?, path)
}

/// Serialize cameras in INRIA `cameras.json` layout (ids are the list positions).
pub fn cameras_json_string(cams: &[Camera]) -> String {
    let entries: Vec<Entry> = cams
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let m = c.world_from_camera_rotation;
            let row = |k: usize| [m.x_axis[k], m.y_axis[k], m.z_axis[k]];
            let centred = c.cx == 0.5 * c.width as f64 && c.cy == 0.5 * c.height as f64;
            Entry {
                id: i as i64,
                img_name: c.name.clone(),
                width: c.width,
                height: c.height,
                position: c.center.to_array(),
                rotation: [row(0), row(1), row(2)],
                fx: c.fx,
                fy: c.fy,
                cx: (!centred).then_some(c.cx),
                cy: (!centred).then_some(c.cy),
            }
        })
        .collect();
    serde_json::to_string_pretty(&entries).expect("cameras serialize")
}
