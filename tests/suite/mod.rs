mod cli;
mod common;
mod golden_drjit;
mod gradients;
mod mitsuba_crosscheck;
mod oracle;
mod raster;
mod readers;
