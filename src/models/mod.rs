//! Model slots (SPEC.md §19): inpainting, depth, video and artifact removal, each with a
//! deterministic classical default.

pub mod telea;
