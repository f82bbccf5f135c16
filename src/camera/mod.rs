//! Pinhole cameras and their readers.
//!
//! Camera frame (SPEC.md §2): OpenCV / COLMAP / gsplat, +x right, +y down, +z forward.
//! A camera stores `world_from_camera` (rotation whose columns are the camera axes in world
//! coordinates, and the camera centre); `camera_from_world` is derived.
//!
//! Readers: INRIA `cameras.json` ([`inria`]), nerfstudio / NeRF-synthetic `transforms.json`
//! ([`transforms`]), COLMAP sparse models in text and binary ([`colmap`]).

pub mod colmap;
pub mod inria;
pub mod transforms;

use crate::error::{Error, Result};
use glam::{DMat3, DVec3};

/// Largest deviation of `RᵀR` from the identity accepted for a camera rotation.
/// Cameras written with 7–9 significant digits (JSON, COLMAP text) sit around 1e-7.
pub const ROTATION_TOLERANCE: f64 = 1e-5;

/// Largest image side accepted for a camera (pixels).
pub const MAX_IMAGE_SIDE: u32 = 1 << 16;
/// Largest image accepted for a camera (pixels): 2^28, a 3 GiB f32 RGB render.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// The camera called `name` in `cams` (read from `file`, named in the error).
pub fn find<'a>(cams: &'a [Camera], name: &str, file: &std::path::Path) -> Result<&'a Camera> {
    cams.iter()
        .find(|c| c.name == name)
        .ok_or_else(|| Error::invalid(format!("no camera named '{name}'")).at(file))
}

/// A pinhole camera (no distortion).
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Focal lengths in pixels.
    pub fx: f64,
    pub fy: f64,
    /// Principal point in pixels; pixel centres are at `(j + 0.5, i + 0.5)`.
    pub cx: f64,
    pub cy: f64,
    /// Rotation part of `world_from_camera` (columns: camera x, y, z axes in world).
    pub world_from_camera_rotation: DMat3,
    /// Camera centre in world coordinates (translation of `world_from_camera`).
    pub center: DVec3,
}

impl Camera {
    /// A camera with the principal point at the image centre, validated.
    pub fn new(
        name: impl Into<String>,
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        world_from_camera_rotation: DMat3,
        center: DVec3,
    ) -> Result<Camera> {
        let cam = Camera {
            name: name.into(),
            width,
            height,
            fx,
            fy,
            cx: 0.5 * width as f64,
            cy: 0.5 * height as f64,
            world_from_camera_rotation,
            center,
        };
        cam.validate()?;
        Ok(cam)
    }

    /// Check sizes, intrinsics and that the rotation is a proper rotation.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::invalid(format!("camera '{}': {what}", self.name)));
        if self.width == 0 || self.height == 0 {
            return bad(format!(
                "image size {}x{} is empty",
                self.width, self.height
            ));
        }
        // A size the renderer's buffers (and its tile grid) could not hold is refused here,
        // before anything is allocated for it.
        if self.width.max(self.height) > MAX_IMAGE_SIDE
            || u64::from(self.width) * u64::from(self.height) > MAX_IMAGE_PIXELS
        {
            return bad(format!(
                "image size {}x{} is larger than {MAX_IMAGE_SIDE} pixels a side or \
                 {MAX_IMAGE_PIXELS} pixels in all",
                self.width, self.height
            ));
        }
        for (n, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!(
                    "focal length {n} = {v} must be finite and positive"
                ));
            }
        }
        for (n, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return bad(format!("principal point {n} = {v} is not finite"));
            }
        }
        if !self.center.is_finite() {
            return bad(format!("centre {:?} is not finite", self.center));
        }
        let r = self.world_from_camera_rotation;
        if !r.is_finite() {
            return bad("rotation has non-finite entries".into());
        }
        let err = (r.transpose() * r - DMat3::IDENTITY).to_cols_array();
        let dev = err.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        if dev > ROTATION_TOLERANCE || r.determinant() < 0.0 {
            return bad(format!(
                "world_from_camera rotation is not a proper rotation (|RᵀR − I| = {dev:.2e}, \
                 det = {:.6})",
                r.determinant()
            ));
        }
        Ok(())
    }

    /// A camera from intrinsics `[fx, fy, cx, cy]` and the world-to-camera transform
    /// `x_cam = r_cw·x_world + t_cw` (`r_cw` row-major; gsplat's `viewmat`), validated. The
    /// centre is `−r_cwᵀ·t_cw`, in f64.
    pub fn from_world_to_camera(
        name: impl Into<String>,
        width: u32,
        height: u32,
        [fx, fy, cx, cy]: [f64; 4],
        r_cw: [[f64; 3]; 3],
        t_cw: [f64; 3],
    ) -> Result<Camera> {
        // Columns of world_from_camera = rows of camera_from_world.
        let rotation = DMat3::from_cols(
            DVec3::from(r_cw[0]),
            DVec3::from(r_cw[1]),
            DVec3::from(r_cw[2]),
        );
        let cam = Camera {
            name: name.into(),
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            world_from_camera_rotation: rotation,
            center: -(rotation * DVec3::from(t_cw)),
        };
        cam.validate()?;
        Ok(cam)
    }

    /// Rotation of `camera_from_world` (the transpose of the world_from_camera rotation).
    pub fn camera_from_world_rotation(&self) -> DMat3 {
        self.world_from_camera_rotation.transpose()
    }

    /// Translation of `camera_from_world`: `-Rᵀ·c`.
    pub fn camera_from_world_translation(&self) -> DVec3 {
        -(self.camera_from_world_rotation() * self.center)
    }

    /// A camera point from a world point.
    pub fn camera_from_world_point(&self, p_world: DVec3) -> DVec3 {
        self.camera_from_world_rotation() * (p_world - self.center)
    }

    /// The world point of pixel `(x, y)` at camera depth `z`, through the pixel centre.
    pub fn pixel_point(&self, x: usize, y: usize, z: f64) -> DVec3 {
        let pc = DVec3::new(
            ((x as f64 + 0.5) - self.cx) / self.fx * z,
            ((y as f64 + 0.5) - self.cy) / self.fy * z,
            z,
        );
        self.world_from_camera_rotation * pc + self.center
    }

    /// Horizontal and vertical field of view in radians.
    pub fn fov_rad(&self) -> (f64, f64) {
        (
            2.0 * (0.5 * self.width as f64 / self.fx).atan(),
            2.0 * (0.5 * self.height as f64 / self.fy).atan(),
        )
    }

    /// A camera at `eye` looking at `target` with `up` pointing up in the image
    /// (image +y points along `-up`). Errors if the view direction is parallel to `up`.
    #[allow(clippy::too_many_arguments)]
    pub fn look_at(
        name: impl Into<String>,
        width: u32,
        height: u32,
        fov_x_rad: f64,
        eye: DVec3,
        target: DVec3,
        up: DVec3,
    ) -> Result<Camera> {
        let z = (target - eye).normalize_or_zero();
        let x = (-up).cross(z).normalize_or_zero();
        if z == DVec3::ZERO || x == DVec3::ZERO {
            return Err(Error::invalid(
                "look_at: view direction is zero or parallel to up",
            ));
        }
        let y = z.cross(x);
        let fx = 0.5 * width as f64 / (0.5 * fov_x_rad).tan();
        Camera::new(name, width, height, fx, fx, DMat3::from_cols(x, y, z), eye)
    }
}

/// Mitsuba 3's camera frame is +x left, +y up, +z forward; ours is +x right, +y down,
/// +z forward. They differ by a rotation of 180° about z: `cv_from_mitsuba = diag(-1, -1, 1)`.
/// This is the one place the conversion is written (test `mitsuba_frame_round_trip`).
pub const CV_FROM_MITSUBA: DMat3 = DMat3::from_cols(
    DVec3::new(-1.0, 0.0, 0.0),
    DVec3::new(0.0, -1.0, 0.0),
    DVec3::new(0.0, 0.0, 1.0),
);

/// Our `world_from_camera` rotation from Mitsuba's sensor `to_world` rotation.
pub fn world_from_camera_from_mitsuba(world_from_mitsuba_camera: DMat3) -> DMat3 {
    // world_from_cv = world_from_mitsuba · mitsuba_from_cv, and mitsuba_from_cv = CV_FROM_MITSUBA
    // (the matrix is its own inverse).
    world_from_mitsuba_camera * CV_FROM_MITSUBA
}

/// Mitsuba's sensor `to_world` rotation from our `world_from_camera` rotation.
pub fn world_from_camera_to_mitsuba(world_from_camera: DMat3) -> DMat3 {
    world_from_camera * CV_FROM_MITSUBA
}

/// OpenGL / Blender / NeRF camera frame (+x right, +y up, +z backward) to ours.
pub const CV_FROM_OPENGL: DMat3 = DMat3::from_cols(
    DVec3::new(1.0, 0.0, 0.0),
    DVec3::new(0.0, -1.0, 0.0),
    DVec3::new(0.0, 0.0, -1.0),
);

/// Read a whole file, naming it in the error.
pub(crate) fn read_file(path: &std::path::Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mitsuba_frame_round_trip() {
        // A Mitsuba look_at camera at the origin looking down world -z with up +y has
        // camera +x pointing to world -x (left in the image).
        let mitsuba = DMat3::from_cols(DVec3::NEG_X, DVec3::Y, DVec3::NEG_Z);
        let ours = world_from_camera_from_mitsuba(mitsuba);
        assert_eq!(ours.x_axis, DVec3::X, "our +x (image right) is world +x");
        assert_eq!(ours.y_axis, DVec3::NEG_Y, "our +y (image down) is world -y");
        assert_eq!(ours.z_axis, DVec3::NEG_Z, "both look along world -z");
        assert_eq!(world_from_camera_to_mitsuba(ours), mitsuba);
        let cam = Camera::look_at("a", 8, 6, 1.0, DVec3::ZERO, DVec3::NEG_Z, DVec3::Y).unwrap();
        assert!((cam.world_from_camera_rotation - ours).abs_diff_eq(DMat3::ZERO, 1e-15));
    }
}
