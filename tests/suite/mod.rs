mod cli;
mod common;
mod golden_drjit;
mod mitsuba_crosscheck;
mod raster;
mod readers;
