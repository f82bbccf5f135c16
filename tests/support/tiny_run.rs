//! The tiny run of the pipeline tests (SPEC.md §20 in seconds): the bundled lounge at
//! 40×30, an original scene trained 300 iterations, the lounge's candidates and evaluation
//! views, and the quick preset shrunk to seconds.
//!
//! ```ignore
//! let t = TempDir::new("pipeline-x");
//! let Tiny { run, inp, cfg } = TinyRun::new().config(|c| c.interpolation = false).build(&t);
//! // For a test of `unseen extrapolate RUN --config CONFIG_FILE`:
//! let (run, config_file) = TinyRun::new().files(&t);
//! ```
use super::{TempDir, reference, walk};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use unseen::pipeline::{Inputs, PipelineConfig, ReconConfig, SlotNames, load_inputs};
use unseen::train::run::train_run;
use unseen::train::trainer::TrainConfig;

/// The bundled lounge: the tiny run's dataset.
pub fn lounge() -> PathBuf {
    reference("scenes/lounge")
}

/// The quick preset shrunk to seconds, with the ground-truth generator.
pub fn tiny_config() -> PipelineConfig {
    let r = |iterations| ReconConfig {
        iterations,
        densify: None,
    };
    PipelineConfig {
        slots: SlotNames::truth(),
        qa_iterations: 30,
        video_frames: 3,
        stage1: r(60),
        stage2: r(60),
        interpolate: r(40),
        fixer_every: 20,
        ..PipelineConfig::quick()
    }
}

/// A tiny run as a test uses it.
pub struct Tiny {
    /// `DIR/run`: the original scene (`unseen train`'s run folder).
    pub run: PathBuf,
    /// The run's inputs: the scene, the candidates, the evaluation views, the lounge.
    pub inp: Inputs,
    /// The configuration.
    pub cfg: PipelineConfig,
}

/// The builder of a [`Tiny`] run: by default the lounge's `candidates.json`, its
/// `evaluation.json` and [`tiny_config`].
pub struct TinyRun {
    candidates: PathBuf,
    evaluation: bool,
    config: PipelineConfig,
}

impl Default for TinyRun {
    fn default() -> Self {
        TinyRun::new()
    }
}

impl TinyRun {
    pub fn new() -> TinyRun {
        TinyRun {
            candidates: lounge().join("candidates.json"),
            evaluation: true,
            config: tiny_config(),
        }
    }

    /// Another candidate list (an INRIA `cameras.json`) instead of the lounge's.
    pub fn candidates(mut self, list: &Path) -> TinyRun {
        self.candidates = list.to_path_buf();
        self
    }

    /// No evaluation views (no metrics).
    pub fn without_evaluation(mut self) -> TinyRun {
        self.evaluation = false;
        self
    }

    /// Change the configuration from [`tiny_config`].
    pub fn config(mut self, change: impl FnOnce(&mut PipelineConfig)) -> TinyRun {
        change(&mut self.config);
        self
    }

    /// The original scene at `dir/run`, its inputs and the configuration.
    pub fn build(self, dir: &Path) -> Tiny {
        let run = self.train(dir);
        let inp = self.inputs(&run);
        Tiny {
            run,
            inp,
            cfg: self.config,
        }
    }

    /// The original scene alone at `dir/run`: 300 iterations on the lounge at 40×30, the
    /// same for every builder.
    pub fn train(&self, dir: &Path) -> PathBuf {
        train(dir)
    }

    /// The inputs of the run `run` (the candidates, the evaluation views, the lounge).
    pub fn inputs(&self, run: &Path) -> Inputs {
        let evaluation = lounge().join("evaluation.json");
        load_inputs(
            run,
            &self.candidates,
            self.evaluation.then_some(evaluation.as_path()),
            Some(&lounge()),
        )
        .unwrap()
    }

    /// For the program's tests: the original scene at `dir/run` and the configuration in
    /// `dir/tiny.json` (`unseen extrapolate RUN --config dir/tiny.json`).
    pub fn files(&self, dir: &Path) -> (PathBuf, PathBuf) {
        (self.train(dir), self.config_file(dir))
    }

    /// The configuration written to `dir/tiny.json`.
    pub fn config_file(&self, dir: &Path) -> PathBuf {
        let p = dir.join("tiny.json");
        std::fs::write(&p, serde_json::to_string(&self.config).unwrap()).unwrap();
        p
    }
}

/// [`TinyRun::train`]. The scene is trained once per test process, in a temporary folder
/// removed at once, and each call writes its files: training is deterministic, so they are
/// the bits a training of each test's own gives (but for `cfg_args`, INRIA's record of the
/// folder trained in, which nothing here reads). This saves ~2 s of CPU per test.
fn train(dir: &Path) -> PathBuf {
    static FILES: OnceLock<Vec<(PathBuf, Vec<u8>)>> = OnceLock::new();
    let files = FILES.get_or_init(|| {
        let t = TempDir::new("tiny-run");
        let run = t.join("run");
        let cfg = TrainConfig {
            iterations: 300,
            resolution: 4,
            save_iterations: vec![],
            ..TrainConfig::default()
        };
        train_run(&lounge(), &run, &cfg, None, Default::default(), &mut |_| {}).unwrap();
        walk(&run)
            .into_iter()
            .map(|p| {
                let bytes = std::fs::read(&p).unwrap();
                (p.strip_prefix(&run).unwrap().to_path_buf(), bytes)
            })
            .collect()
    });
    let run = dir.join("run");
    for (rel, bytes) in files {
        let p = run.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, bytes).unwrap();
    }
    run
}
