//! Depth-image-based geometry: alignment of estimated depth to metric depth ([`align`]).

pub mod align;
