//! Small fixed-size maths: the crate's own `exp`/`ln`, real spherical harmonics.

pub mod fastexp;
pub mod sh;
