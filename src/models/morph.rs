//! `morph`: the deterministic default video generator (SPEC.md §19.3). Frames between two
//! keyframes at interpolated poses, each rendered by DIBR-warping both keyframes with their
//! depths, blending by z-test and by the distance along the path, and filling what neither
//! keyframe saw with Telea (colour) and depth-fill (depth).

use super::classical::{COLOR_SPAN, DEPTH_SPAN};
use super::telea::inpaint_float;
use super::{Keyframe, Video, VideoGenerator};
use crate::camera::Camera;
use crate::error::{Error, ErrorKind, Result};
use crate::io::image::ImageF32;
use crate::warp::dibr::{WarpOptions, Warped, warp};
use glam::{DMat3, DQuat};

/// The error of a clip in which some intermediate camera sees neither end frame.
pub const NO_VISIBLE_END: &str = "neither end frame is visible from an intermediate camera";

/// The error of a clip between end frames of different sizes (a clip has one size).
pub const END_SIZES_DIFFER: &str = "the end frames differ in size or channels";

/// Whether `e` says that a clip cannot be made between its two keyframes (an intermediate
/// camera sees neither, or they differ in size) rather than that something failed: the
/// pipeline records such a clip and leaves it out (SPEC.md §20.3–20.4). Decided by the
/// error's kind ([`ErrorKind::Degenerate`]), never by its text; the kind also marks a
/// clip's video depth that no alignment fits, so apply this to a clip's generation only.
pub fn cannot_make_clip(e: &Error) -> bool {
    e.kind == ErrorKind::Degenerate
}

/// Settings of [`Morph`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Morph {
    /// How each keyframe is warped (default: nearest, crack closing radius 1).
    pub warp: WarpOptions,
    /// Relative depth band in which both keyframes see the same surface and are blended.
    pub blend_tolerance: f32,
    /// Telea radius for the invented pixels (colour and depth).
    pub fill_radius: f64,
}

impl Default for Morph {
    fn default() -> Self {
        Morph {
            warp: WarpOptions {
                close_cracks: 1,
                ..WarpOptions::default()
            },
            blend_tolerance: 0.02,
            fill_radius: 3.0,
        }
    }
}

/// The camera at `t ∈ [0, 1]` between `a` and `b` (same image size): rotation by slerp
/// of the unit quaternions (shortest arc), centre and intrinsics by linear interpolation.
pub fn interpolate_camera(a: &Camera, b: &Camera, t: f64, name: String) -> Result<Camera> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(Error::invalid(format!(
            "cameras '{}' ({}x{}) and '{}' ({}x{}) differ in size",
            a.name, a.width, a.height, b.name, b.width, b.height
        )));
    }
    let qa = DQuat::from_mat3(&a.world_from_camera_rotation).normalize();
    let mut qb = DQuat::from_mat3(&b.world_from_camera_rotation).normalize();
    if qa.dot(qb) < 0.0 {
        qb = -qb;
    }
    let q = slerp(qa, qb, t);
    let lerp = |x: f64, y: f64| x + (y - x) * t;
    let cam = Camera {
        name,
        width: a.width,
        height: a.height,
        fx: lerp(a.fx, b.fx),
        fy: lerp(a.fy, b.fy),
        cx: lerp(a.cx, b.cx),
        cy: lerp(a.cy, b.cy),
        world_from_camera_rotation: DMat3::from_quat(q),
        center: a.center + (b.center - a.center) * t,
    };
    cam.validate()?;
    Ok(cam)
}

/// `(sin((1−t)θ)·a + sin(tθ)·b) / sin θ` with `cos θ = a·b ≥ 0`; the linear blend,
/// normalized, when the quaternions are within 1e-9 (θ → 0).
fn slerp(a: DQuat, b: DQuat, t: f64) -> DQuat {
    let c = a.dot(b).min(1.0);
    let theta = c.acos();
    let s = theta.sin();
    if s < 1e-9 {
        return (a * (1.0 - t) + b * t).normalize();
    }
    (a * (((1.0 - t) * theta).sin() / s) + b * ((t * theta).sin() / s)).normalize()
}

impl VideoGenerator for Morph {
    fn name(&self) -> &str {
        "morph"
    }

    fn generate(&self, start: Keyframe, end: Keyframe, n: usize) -> Result<Video> {
        if n < 2 {
            return Err(Error::invalid(format!(
                "a clip needs at least its 2 end frames, asked for {n}"
            )));
        }
        let (Some(da), Some(db)) = (start.depth, end.depth) else {
            return Err(Error::invalid(
                "morph warps the end frames by their depth: both depths are needed",
            ));
        };
        let (ia, ib) = (start.image, end.image);
        if (ia.width, ia.height, ia.channels) != (ib.width, ib.height, ib.channels) {
            return Err(Error::degenerate(END_SIZES_DIFFER));
        }
        let (w, h, ch) = (ia.width, ia.height, ia.channels);
        let mut video = Video {
            frames: Vec::with_capacity(n),
            cameras: Vec::with_capacity(n),
            depths: Some(Vec::with_capacity(n)),
            invented: Some(Vec::with_capacity(n)),
        };
        for k in 0..n {
            let t = k as f64 / (n - 1) as f64;
            let name = format!("{}_{}_{k:03}", start.camera.name, end.camera.name);
            let cam = if k == 0 {
                start.camera.clone()
            } else if k == n - 1 {
                end.camera.clone()
            } else {
                interpolate_camera(start.camera, end.camera, t, name)?
            };
            let (img, depth, invented) = if k == 0 {
                (ia.clone(), da.to_vec(), vec![false; w * h])
            } else if k == n - 1 {
                (ib.clone(), db.to_vec(), vec![false; w * h])
            } else {
                let a = warp(ia, da, start.camera, &cam, &self.warp)?;
                let b = warp(ib, db, end.camera, &cam, &self.warp)?;
                self.blend(&a, &b, t as f32, ch)?
            };
            video.frames.push(img);
            video.cameras.push(cam);
            video.depths.as_mut().expect("set").push(depth);
            video.invented.as_mut().expect("set").push(invented);
        }
        Ok(video)
    }
}

impl Morph {
    /// Blend two warps of one frame (`t`: the end frame's share), then fill.
    fn blend(
        &self,
        a: &Warped,
        b: &Warped,
        t: f32,
        ch: usize,
    ) -> Result<(ImageF32, Vec<f32>, Vec<bool>)> {
        let (w, h) = (a.image.width, a.image.height);
        let tol = 1.0 + self.blend_tolerance;
        let mut img = vec![0f32; w * h * ch];
        let mut z = vec![0f32; w * h];
        let mut invented = vec![false; w * h];
        for p in 0..w * h {
            let (ha, hb) = (a.holes[p], b.holes[p]);
            let (za, zb) = (a.depth[p], b.depth[p]);
            let ca = &a.image.data[p * ch..(p + 1) * ch];
            let cb = &b.image.data[p * ch..(p + 1) * ch];
            let out = &mut img[p * ch..(p + 1) * ch];
            match (ha, hb) {
                (false, false) if za <= zb * tol && zb <= za * tol => {
                    for c in 0..ch {
                        out[c] = (1.0 - t) * ca[c] + t * cb[c];
                    }
                    z[p] = (1.0 - t) * za + t * zb;
                }
                (false, false) if za < zb => {
                    out.copy_from_slice(ca);
                    z[p] = za;
                }
                (false, _) if hb => {
                    out.copy_from_slice(ca);
                    z[p] = za;
                }
                (_, false) => {
                    out.copy_from_slice(cb);
                    z[p] = zb;
                }
                _ => invented[p] = true,
            }
        }
        if invented.iter().all(|&v| v) {
            return Err(Error::degenerate(NO_VISIBLE_END));
        }
        let img = inpaint_float(&img, w, h, ch, &invented, self.fill_radius, COLOR_SPAN)?;
        let z = inpaint_float(&z, w, h, 1, &invented, self.fill_radius, DEPTH_SPAN)?;
        Ok((ImageF32::new(w, h, ch, img)?, z, invented))
    }
}
