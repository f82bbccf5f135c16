//! The steps of a run as one type (SPEC.md §20.8): every step folder of a run directory is a
//! [`Step`], written and parsed only here (`Display` / `FromStr`), with the [`Stage`] it
//! belongs to and its place in pipeline order. The runner, `compare`, the audit's step
//! sharing and report and the batch fan-out read steps from this type, never from string
//! literals (test `step_names_live_in_steps_rs`).

use crate::error::{Error, Result};
use std::fmt;
use std::str::FromStr;

/// One step of a run, named by its folder under the run directory.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Step {
    /// `views`: independent-view detection and the plan (SPEC.md §20.2).
    Views,
    /// `stage1/<view>`: one independent view's inpainting and depth (the view's file stem).
    Independent(String),
    /// `stage1/propagate`: DIBR propagation of the independent views.
    Propagate,
    /// `qa/<scene>`: the QA-Mask fine-tuned on a scene (`original`, `stage1`, `stage2`).
    QaMask(String),
    /// `stage1/recon`: the stage-1 reconstruction.
    Stage1Recon,
    /// `stage2/dependent`: the dependent views.
    Dependent,
    /// `stage2/videos`: the videos between keyframes.
    Videos,
    /// `stage2/recon`: the stage-2 reconstruction.
    Stage2Recon,
    /// `interpolate/fixer`: the artifact fixer's frames.
    Fixer,
    /// `interpolate/recon`: the interpolation stage's reconstruction.
    Interpolation,
    /// `eval/masks`: the evaluation masks.
    EvalMasks,
    /// `eval/<scene>`: one scene's evaluation.
    Eval(String),
}

/// The stages of a run, in order: what the audit reports costs by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stage {
    Views,
    QaMask,
    Stage1,
    Stage2,
    Interpolate,
    Eval,
}

impl Stage {
    pub const ALL: [Stage; 6] = [
        Stage::Views,
        Stage::QaMask,
        Stage::Stage1,
        Stage::Stage2,
        Stage::Interpolate,
        Stage::Eval,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Views => "views",
            Stage::QaMask => "qa-mask",
            Stage::Stage1 => "stage1",
            Stage::Stage2 => "stage2",
            Stage::Interpolate => "interpolate",
            Stage::Eval => "eval",
        }
    }

    /// The folder under a run directory that holds the stage's steps (`qa` for the
    /// QA-Mask's; the views step is its own folder).
    pub fn dir(self, root: &std::path::Path) -> std::path::PathBuf {
        root.join(match self {
            Stage::QaMask => "qa",
            s => s.name(),
        })
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Step {
    /// The stage the step belongs to.
    pub fn stage(&self) -> Stage {
        match self {
            Step::Views => Stage::Views,
            Step::QaMask(_) => Stage::QaMask,
            Step::Independent(_) | Step::Propagate | Step::Stage1Recon => Stage::Stage1,
            Step::Dependent | Step::Videos | Step::Stage2Recon => Stage::Stage2,
            Step::Fixer | Step::Interpolation => Stage::Interpolate,
            Step::EvalMasks | Step::Eval(_) => Stage::Eval,
        }
    }

    /// The step's place in pipeline order (ties broken by name): the order `compare`
    /// lists steps in. The QA-Mask of a scene comes after the step that made the scene.
    pub fn rank(&self) -> u32 {
        match self {
            Step::Views => 0,
            Step::Independent(_) => 1,
            Step::Propagate => 2,
            Step::QaMask(s) if s == "original" => 3,
            Step::Stage1Recon => 4,
            Step::Dependent => 5,
            Step::Videos => 6,
            Step::QaMask(s) if s == "stage1" => 7,
            Step::Stage2Recon => 8,
            Step::Fixer => 9,
            Step::QaMask(s) if s == "stage2" => 10,
            Step::QaMask(_) => 10,
            Step::Interpolation => 11,
            Step::EvalMasks | Step::Eval(_) => 12,
        }
    }

    /// The step's folder under the run directory `root`.
    pub fn dir(&self, root: &std::path::Path) -> std::path::PathBuf {
        root.join(self.to_string())
    }
}

impl fmt::Display for Step {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Step::Views => f.write_str("views"),
            Step::Independent(v) => write!(f, "stage1/{v}"),
            Step::Propagate => f.write_str("stage1/propagate"),
            Step::QaMask(s) => write!(f, "qa/{s}"),
            Step::Stage1Recon => f.write_str("stage1/recon"),
            Step::Dependent => f.write_str("stage2/dependent"),
            Step::Videos => f.write_str("stage2/videos"),
            Step::Stage2Recon => f.write_str("stage2/recon"),
            Step::Fixer => f.write_str("interpolate/fixer"),
            Step::Interpolation => f.write_str("interpolate/recon"),
            Step::EvalMasks => f.write_str("eval/masks"),
            Step::Eval(s) => write!(f, "eval/{s}"),
        }
    }
}

impl FromStr for Step {
    type Err = Error;

    /// A step's folder name back to the step; anything else is an error naming it.
    fn from_str(s: &str) -> Result<Step> {
        let bad = || {
            Error::invalid(format!(
                "'{s}' is not a step of a run (views, stage1/<view>, stage1/propagate, qa/<scene>, stage1/recon, stage2/dependent, stage2/videos, stage2/recon, interpolate/fixer, interpolate/recon, eval/masks, eval/<scene>)"
            ))
        };
        let one = |rest: &str| {
            (!rest.is_empty() && !rest.contains('/'))
                .then(|| rest.to_string())
                .ok_or_else(bad)
        };
        Ok(match s {
            "views" => Step::Views,
            "stage1/propagate" => Step::Propagate,
            "stage1/recon" => Step::Stage1Recon,
            "stage2/dependent" => Step::Dependent,
            "stage2/videos" => Step::Videos,
            "stage2/recon" => Step::Stage2Recon,
            "interpolate/fixer" => Step::Fixer,
            "interpolate/recon" => Step::Interpolation,
            "eval/masks" => Step::EvalMasks,
            _ => {
                let (head, rest) = s.split_once('/').ok_or_else(bad)?;
                match head {
                    "stage1" => Step::Independent(one(rest)?),
                    "qa" => Step::QaMask(one(rest)?),
                    "eval" => Step::Eval(one(rest)?),
                    _ => return Err(bad()),
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every step's name parses back to the step; names that are not steps are errors.
    #[test]
    fn step_names_round_trip() {
        let all = [
            Step::Views,
            Step::Independent("view_07".into()),
            Step::Propagate,
            Step::QaMask("original".into()),
            Step::Stage1Recon,
            Step::Dependent,
            Step::Videos,
            Step::QaMask("stage1".into()),
            Step::Stage2Recon,
            Step::Fixer,
            Step::QaMask("stage2".into()),
            Step::Interpolation,
            Step::EvalMasks,
            Step::Eval("stage2".into()),
        ];
        for s in &all {
            assert_eq!(s.to_string().parse::<Step>().unwrap(), *s);
        }
        // Pipeline order is the order above.
        assert!(
            all.windows(2).all(|w| w[0].rank() <= w[1].rank()),
            "{all:?}"
        );
        for bad in [
            "", "stage1", "stage1/", "stage3/x", "qa/a/b", "eval", "view",
        ] {
            assert!(bad.parse::<Step>().is_err(), "{bad}");
        }
        assert_eq!(Step::Stage1Recon.stage().name(), "stage1");
        assert_eq!(Step::QaMask("x".into()).stage().name(), "qa-mask");
    }
}
