//! Depth-image-based geometry: forward warping ([`dibr`]) and alignment of estimated depth
//! to metric depth ([`align`]).

pub mod align;
pub mod dibr;
