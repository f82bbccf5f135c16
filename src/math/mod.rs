//! Small fixed-size maths: the crate's own `exp`/`ln`, libm-free `floor`/`ceil`, real
//! spherical harmonics.

pub mod fastexp;
pub mod round;
pub mod sh;
