//! Collision tests between convex polyhedra (the paper's §3.3.1 view-frustum collisions):
//! our own GJK on support maps ([`gjk`]).

pub mod gjk;
pub mod independent;
