//! Small fixed-size maths: the crate's own `exp`/`ln`, libm-free `floor`/`ceil`, real
//! spherical harmonics, and the lane type per-Gaussian code is written in.

pub mod fastexp;
pub mod hull;
pub mod lanes;
pub mod round;
pub mod sh;
