//! Runs on a batch engine (SPEC.md §21.4): what a job costs ([`cost`]), a Slurm submission
//! folder ([`slurm`]), and the waves of one extrapolation derived from its plan
//! ([`extrapolate`]). Both `unseen extrapolate --emit-slurm` and the audit's fan-out
//! (`crate::audit::cluster`) write their submissions through this module; nothing here
//! schedules: Slurm does.

pub mod cost;
pub mod extrapolate;
pub mod slurm;

pub use cost::{Cost, Request, least_request, pipeline_cost, pipeline_work, request};
pub use slurm::{ArrayWave, SlurmOptions, shell_quote, write_submission};
