//! COLMAP sparse models (`cameras`, `images`, `points3D`), text and binary.
//!
//! COLMAP stores `camera_from_world` per image as a wxyz quaternion and a translation, in the
//! OpenCV camera frame. Only undistorted models are accepted (`SIMPLE_PINHOLE`, `PINHOLE`);
//! any other model is a clear [`ErrorKind::Unsupported`](crate::error::ErrorKind) error that
//! names it, since silently ignoring distortion would render the wrong image.
//!
//! Binary layout (COLMAP `src/colmap/scene/reconstruction_io.cc`), little-endian:
//! `cameras.bin`: u64 n, then n × (i32 id, i32 model, u64 width, u64 height, f64 params[]);
//! `images.bin`: u64 n, then n × (i32 id, f64 qw qx qy qz, f64 tx ty tz, i32 camera_id,
//! NUL-terminated name, u64 n2d, n2d × (f64 x, f64 y, i64 point3d_id));
//! `points3D.bin`: u64 n, then n × (u64 id, f64 xyz\[3\], u8 rgb\[3\], f64 error, u64 len,
//! len × (i32 image_id, i32 point2d_idx)).

use super::{Camera, read_file};
use crate::error::{Error, Result};
use glam::{DMat3, DQuat, DVec3};
use std::collections::BTreeMap;
use std::path::Path;

/// A 3D point of the sparse model.
#[derive(Clone, Debug, PartialEq)]
pub struct Point3D {
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    pub error: f64,
}

/// A sparse model: one camera per registered image (sorted by image name) and the points.
#[derive(Clone, Debug, Default)]
pub struct ColmapModel {
    pub cameras: Vec<Camera>,
    pub points: Vec<Point3D>,
}

/// COLMAP camera model ids and parameter counts, in COLMAP's order.
const MODELS: [(&str, usize); 11] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
];

#[derive(Clone, Debug)]
struct Intrinsics {
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
}

fn intrinsics(path: &Path, model: &str, w: u64, h: u64, p: &[f64]) -> Result<Intrinsics> {
    let (fx, fy, cx, cy) = match model {
        "SIMPLE_PINHOLE" => (p[0], p[0], p[1], p[2]),
        "PINHOLE" => (p[0], p[1], p[2], p[3]),
        other => {
            return Err(Error::unsupported(
                path,
                format!(
                    "camera model {other} has lens distortion; undistort the images first \
                     (colmap image_undistorter) so the model is PINHOLE or SIMPLE_PINHOLE"
                ),
            ));
        }
    };
    let (width, height) = (u32::try_from(w), u32::try_from(h));
    match (width, height) {
        (Ok(width), Ok(height)) => Ok(Intrinsics {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
        }),
        _ => Err(Error::parse(
            path,
            format!("image size {w}x{h} is out of range"),
        )),
    }
}

/// Read a sparse model directory holding either `.bin` or `.txt` files (binary preferred).
pub fn read_colmap_model(dir: &Path) -> Result<ColmapModel> {
    let bin = dir.join("cameras.bin").exists();
    let ext = if bin { "bin" } else { "txt" };
    let (cams_p, imgs_p, pts_p) = (
        dir.join(format!("cameras.{ext}")),
        dir.join(format!("images.{ext}")),
        dir.join(format!("points3D.{ext}")),
    );
    let (intr, images, points) = if bin {
        (
            parse_cameras_bin(&read_file(&cams_p)?, &cams_p)?,
            parse_images_bin(&read_file(&imgs_p)?, &imgs_p)?,
            if pts_p.exists() {
                parse_points_bin(&read_file(&pts_p)?, &pts_p)?
            } else {
                Vec::new()
            },
        )
    } else {
        (
            parse_cameras_txt(&read_text(&cams_p)?, &cams_p)?,
            parse_images_txt(&read_text(&imgs_p)?, &imgs_p)?,
            if pts_p.exists() {
                parse_points_txt(&read_text(&pts_p)?, &pts_p)?
            } else {
                Vec::new()
            },
        )
    };
    let mut cameras = Vec::with_capacity(images.len());
    for img in images {
        let k = intr.get(&img.camera_id).ok_or_else(|| {
            Error::parse(
                &imgs_p,
                format!(
                    "image '{}' uses camera {} which is not defined",
                    img.name, img.camera_id
                ),
            )
        })?;
        let q = img.qvec;
        let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
        if !(n > 0.0 && n.is_finite() && img.tvec.iter().all(|t| t.is_finite())) {
            return Err(Error::parse(
                &imgs_p,
                format!("image '{}' has an invalid pose", img.name),
            ));
        }
        let camera_from_world =
            DMat3::from_quat(DQuat::from_xyzw(q[1] / n, q[2] / n, q[3] / n, q[0] / n));
        let world_from_camera = camera_from_world.transpose();
        let center = -(world_from_camera * DVec3::from_array(img.tvec));
        let mut cam = Camera::new(
            img.name,
            k.width,
            k.height,
            k.fx,
            k.fy,
            world_from_camera,
            center,
        )
        .map_err(|e| e.at(&imgs_p))?;
        cam.cx = k.cx;
        cam.cy = k.cy;
        cam.validate().map_err(|e| e.at(&cams_p))?;
        cameras.push(cam);
    }
    cameras.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(ColmapModel { cameras, points })
}

fn read_text(path: &Path) -> Result<String> {
    String::from_utf8(read_file(path)?).map_err(|_| Error::parse(path, "file is not UTF-8 text"))
}

struct ImageEntry {
    name: String,
    camera_id: i64,
    qvec: [f64; 4],
    tvec: [f64; 3],
}

/// Lines that are not comments or blank, with their 1-based line numbers.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

fn field<T: std::str::FromStr>(
    path: &Path,
    line: usize,
    tok: Option<&str>,
    what: &str,
) -> Result<T> {
    tok.and_then(|t| t.parse().ok())
        .ok_or_else(|| Error::parse(path, format!("line {line}: missing or invalid {what}")))
}

fn parse_cameras_txt(text: &str, path: &Path) -> Result<BTreeMap<i64, Intrinsics>> {
    let mut out = BTreeMap::new();
    for (ln, l) in data_lines(text) {
        let mut t = l.split_whitespace();
        let id: i64 = field(path, ln, t.next(), "camera id")?;
        let model = t
            .next()
            .ok_or_else(|| Error::parse(path, format!("line {ln}: no model")))?;
        let nparams = MODELS
            .iter()
            .find(|m| m.0 == model)
            .map(|m| m.1)
            .ok_or_else(|| Error::unsupported(path, format!("line {ln}: unknown model {model}")))?;
        let w: u64 = field(path, ln, t.next(), "width")?;
        let h: u64 = field(path, ln, t.next(), "height")?;
        let mut p = Vec::with_capacity(nparams);
        for k in 0..nparams {
            p.push(field::<f64>(path, ln, t.next(), &format!("parameter {k}"))?);
        }
        out.insert(id, intrinsics(path, model, w, h, &p)?);
    }
    Ok(out)
}

fn parse_images_txt(text: &str, path: &Path) -> Result<Vec<ImageEntry>> {
    // Each image takes two lines; the second (2D points) may be empty, so walk raw lines.
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
    while let Some((ln, l)) = lines.next() {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let mut t = l.split_whitespace();
        let _id: i64 = field(path, ln, t.next(), "image id")?;
        let mut q = [0.0; 4];
        for (k, v) in q.iter_mut().enumerate() {
            *v = field(path, ln, t.next(), &format!("quaternion component {k}"))?;
        }
        let mut tv = [0.0; 3];
        for (k, v) in tv.iter_mut().enumerate() {
            *v = field(path, ln, t.next(), &format!("translation component {k}"))?;
        }
        let camera_id: i64 = field(path, ln, t.next(), "camera id")?;
        let name: String = field(path, ln, t.next(), "image name")?;
        out.push(ImageEntry {
            name,
            camera_id,
            qvec: q,
            tvec: tv,
        });
        lines.next(); // the POINTS2D line
    }
    Ok(out)
}

fn parse_points_txt(text: &str, path: &Path) -> Result<Vec<Point3D>> {
    let mut out = Vec::new();
    for (ln, l) in data_lines(text) {
        let mut t = l.split_whitespace();
        let id: u64 = field(path, ln, t.next(), "point id")?;
        let mut xyz = [0.0; 3];
        for v in xyz.iter_mut() {
            *v = field(path, ln, t.next(), "coordinate")?;
        }
        let mut rgb = [0u8; 3];
        for v in rgb.iter_mut() {
            *v = field(path, ln, t.next(), "colour")?;
        }
        let error: f64 = field(path, ln, t.next(), "error")?;
        out.push(Point3D {
            id,
            xyz,
            rgb,
            error,
        });
    }
    Ok(out)
}

/// Bounds-checked little-endian cursor: every read that would run past the end is a
/// parse error naming the file and offset, so malformed input never panics.
struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if self.data.len() - self.pos < n {
            return Err(Error::parse(
                self.path,
                format!("file ends at byte {} while reading {what}", self.data.len()),
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.take(1, what)?[0])
    }
    fn i32(&mut self, what: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
    fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
    fn f64(&mut self, what: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
    /// A count of records of `record_bytes` each, checked against the bytes left.
    fn count(&mut self, record_bytes: usize, what: &str) -> Result<usize> {
        let n = self.u64(what)?;
        let left = (self.data.len() - self.pos) as u64;
        if n.checked_mul(record_bytes as u64).is_none_or(|b| b > left) {
            return Err(Error::parse(
                self.path,
                format!(
                    "{what} = {n} at byte {} exceeds the file size",
                    self.pos - 8
                ),
            ));
        }
        Ok(n as usize)
    }
    fn cstr(&mut self, what: &str) -> Result<String> {
        let rest = &self.data[self.pos..];
        let end = rest.iter().position(|&b| b == 0).ok_or_else(|| {
            Error::parse(
                self.path,
                format!("unterminated {what} at byte {}", self.pos),
            )
        })?;
        let s = String::from_utf8(rest[..end].to_vec()).map_err(|_| {
            Error::parse(
                self.path,
                format!("{what} at byte {} is not UTF-8", self.pos),
            )
        })?;
        self.pos += end + 1;
        Ok(s)
    }
}

fn parse_cameras_bin(data: &[u8], path: &Path) -> Result<BTreeMap<i64, Intrinsics>> {
    let mut c = Cursor { data, pos: 0, path };
    let n = c.count(24, "camera count")?;
    let mut out = BTreeMap::new();
    for _ in 0..n {
        let id = c.i32("camera id")? as i64;
        let model_id = c.i32("camera model")?;
        let (name, nparams) = usize::try_from(model_id)
            .ok()
            .and_then(|m| MODELS.get(m))
            .copied()
            .ok_or_else(|| {
                Error::unsupported(path, format!("unknown camera model id {model_id}"))
            })?;
        let w = c.u64("width")?;
        let h = c.u64("height")?;
        let mut p = [0.0; 12];
        for v in p.iter_mut().take(nparams) {
            *v = c.f64("camera parameter")?;
        }
        out.insert(id, intrinsics(path, name, w, h, &p[..nparams])?);
    }
    Ok(out)
}

fn parse_images_bin(data: &[u8], path: &Path) -> Result<Vec<ImageEntry>> {
    let mut c = Cursor { data, pos: 0, path };
    let n = c.count(72, "image count")?;
    let mut out = Vec::new();
    for _ in 0..n {
        let _id = c.i32("image id")?;
        let mut q = [0.0; 4];
        for v in q.iter_mut() {
            *v = c.f64("quaternion")?;
        }
        let mut tv = [0.0; 3];
        for v in tv.iter_mut() {
            *v = c.f64("translation")?;
        }
        let camera_id = c.i32("camera id")? as i64;
        let name = c.cstr("image name")?;
        let n2d = c.count(24, "2D point count")?;
        c.take(n2d * 24, "2D points")?;
        out.push(ImageEntry {
            name,
            camera_id,
            qvec: q,
            tvec: tv,
        });
    }
    Ok(out)
}

fn parse_points_bin(data: &[u8], path: &Path) -> Result<Vec<Point3D>> {
    let mut c = Cursor { data, pos: 0, path };
    let n = c.count(43, "point count")?;
    let mut out = Vec::new();
    for _ in 0..n {
        let id = c.u64("point id")?;
        let mut xyz = [0.0; 3];
        for v in xyz.iter_mut() {
            *v = c.f64("point coordinate")?;
        }
        let rgb = [c.u8("colour")?, c.u8("colour")?, c.u8("colour")?];
        let error = c.f64("reprojection error")?;
        let len = c.count(8, "track length")?;
        c.take(len * 8, "track")?;
        out.push(Point3D {
            id,
            xyz,
            rgb,
            error,
        });
    }
    Ok(out)
}

/// Parse all three binary files from memory (for fuzzing and tests): returns the model or
/// the first error. `cameras`, `images`, `points` are the file contents.
pub fn parse_colmap_bin(cameras: &[u8], images: &[u8], points: &[u8]) -> Result<usize> {
    let p = Path::new("<memory>");
    let a = parse_cameras_bin(cameras, p)?.len();
    let b = parse_images_bin(images, p)?.len();
    let d = parse_points_bin(points, p)?.len();
    Ok(a + b + d)
}
