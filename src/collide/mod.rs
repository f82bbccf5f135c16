//! Collision tests between convex polyhedra (the paper's §3.3.1 view-frustum collisions):
//! our own GJK on support maps ([`gjk`]), the frustums of inpainted regions ([`frustum`])
//! and the selection of independent views ([`independent`]).

pub mod frustum;
pub mod gjk;
pub mod independent;
