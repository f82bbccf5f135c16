//! Small fixed-size maths: the crate's own `exp`/`ln`, libm-free `floor`/`ceil`, real
//! spherical harmonics, the lane type per-Gaussian code is written in, and the f64 rotation
//! of a quaternion the error bounds and the f64 twins use.

pub mod fastexp;
pub mod hull;
pub mod lanes;
pub mod round;
pub mod sh;

/// The rotation (row-major) of a wxyz quaternion normalized in f64: `|q|² = (w² + x²) + (y²
/// + z²)`, then the textbook matrix. For f64 references and error bounds (the f32 forward
/// uses `raster::project::quat_to_rotmat` on its own normalization).
pub fn rotation_f64(q: [f64; 4]) -> [[f64; 3]; 3] {
    let qn = ((q[0] * q[0] + q[1] * q[1]) + (q[2] * q[2] + q[3] * q[3])).sqrt();
    let [w, x, y, z] = q.map(|v| v / qn);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}
