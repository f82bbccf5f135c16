mod common;
mod golden_drjit;
mod mitsuba_crosscheck;
