//! What a run starts from: the trained scene, its dataset, the candidate cameras and the
//! evaluation poses, read and checked once ([`load_inputs`]), with the digest every step's
//! key includes.

use crate::camera::Camera;
use crate::camera::inria::read_cameras_json;
use crate::dataset::{Dataset, downscale_camera};
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::gaussian::ply::read_ply;
use crate::io::sha256_hex;
use crate::train::run::{latest_ply, load_dataset, load_options, read_config, read_train_views};
use std::path::{Path, PathBuf};

/// Names a candidate may not have: its stage-1 folder would be another step's.
pub const RESERVED_VIEW_NAMES: [&str; 2] = ["recon", "propagate"];

/// What the pipeline starts from.
pub struct Inputs {
    /// The `unseen train` run (the original scene).
    pub run: PathBuf,
    pub scene: Gaussians,
    /// The training iterations that made the scene (its PLY's `iteration_<n>`): where a
    /// fine-tune continuing its schedule starts (`FineTuneRates::Continue`).
    pub scene_iterations: u32,
    /// sha256 of the scene's PLY bytes.
    pub scene_sha256: String,
    /// The run's dataset at its resolution; `train` lists the run's training views.
    pub data: Dataset,
    /// Candidate extrapolation cameras at the run's resolution.
    pub candidates: Vec<Camera>,
    /// sha256 of the candidates' cameras.json bytes.
    pub candidates_sha256: String,
    /// Evaluation poses (indices into `data.views`, with truth); may be empty.
    pub evaluation: Vec<usize>,
    pub background: [f32; 3],
    /// sha256 of everything above that a step may read (scene, cameras, images, depths,
    /// splits, background) and of the crate and conventions versions: part of every
    /// step's key (SPEC.md §20.8).
    pub digest: String,
}

/// The digest of [`Inputs`]: every view's camera, image and depth bits, the splits, the
/// scene and candidates' file hashes, the background, the versions.
fn inputs_digest(
    data: &Dataset,
    scene_sha256: &str,
    candidates: &[Camera],
    evaluation: &[usize],
    background: [f32; 3],
) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    let text = |h: &mut Sha256, s: &str| {
        h.update((s.len() as u64).to_le_bytes());
        h.update(s.as_bytes());
    };
    let floats = |h: &mut Sha256, v: &[f32]| {
        h.update((v.len() as u64).to_le_bytes());
        for x in v {
            h.update(x.to_bits().to_le_bytes());
        }
    };
    text(&mut h, env!("CARGO_PKG_VERSION"));
    h.update(crate::version::CONVENTIONS_VERSION.to_le_bytes());
    h.update(crate::version::NUMERICS_REVISION.to_le_bytes());
    text(&mut h, scene_sha256);
    text(
        &mut h,
        &crate::camera::inria::cameras_json_string(candidates),
    );
    floats(&mut h, &background);
    for v in &data.views {
        text(
            &mut h,
            &crate::camera::inria::cameras_json_string(std::slice::from_ref(&v.camera)),
        );
        floats(&mut h, &v.image.data);
        floats(&mut h, v.depth.as_deref().unwrap_or(&[]));
    }
    for list in [&data.train, &data.test, &data.heldout, &evaluation.to_vec()] {
        h.update((list.len() as u64).to_le_bytes());
        for &i in list.iter() {
            h.update((i as u64).to_le_bytes());
        }
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Load a run, its dataset (from the run's manifest unless `dataset` is given), the
/// candidate cameras and, optionally, the evaluation cameras (their truth must be in the
/// dataset).
pub fn load_inputs(
    run: &Path,
    candidates: &Path,
    evaluation: Option<&Path>,
    dataset: Option<&Path>,
) -> Result<Inputs> {
    if !run.join("config.json").is_file() {
        return Err(Error::invalid("not an `unseen train` run directory (no config.json)").at(run));
    }
    crate::train::run::require_default_conventions(run, "the pipeline")?;
    let cfg = read_config(run)?;
    let (scene_iterations, ply) = latest_ply(run)?;
    let bytes = std::fs::read(&ply).map_err(|e| Error::io(&ply, e))?;
    let scene_sha256 = sha256_hex(&bytes);
    // The scene must be the one the run wrote (a reused folder may hold a newer-numbered
    // PLY of another run).
    let manifest = crate::io::manifest::Manifest::read(run)?;
    let rel = ply.strip_prefix(run).unwrap_or(&ply).display().to_string();
    if !manifest
        .files
        .iter()
        .any(|f| f.path == rel && f.sha256 == scene_sha256)
    {
        return Err(Error::invalid(
            "this PLY is not the one the run's manifest.json lists (a stale file of another run?)",
        )
        .at(&ply));
    }
    let (scene, _) = read_ply(&ply)?;
    if scene.is_empty() {
        return Err(Error::invalid("the scene has no Gaussians").at(&ply));
    }
    let data_dir = match dataset {
        Some(d) => d.to_path_buf(),
        None => {
            let m = crate::io::manifest::Manifest::read(run)?;
            PathBuf::from(
                m.inputs
                    .get("dataset")
                    .and_then(|d| d.as_str())
                    .ok_or_else(|| {
                        Error::parse(
                            &run.join("manifest.json"),
                            "no \"dataset\" path (pass --dataset)",
                        )
                    })?,
            )
        }
    };
    let mut data = load_dataset(&data_dir, &cfg)?;
    let names = read_train_views(run)?;
    let train: Vec<usize> = names
        .iter()
        .map(|n| {
            data.views
                .iter()
                .position(|v| &v.camera.name == n)
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "training view '{n}' of the run is not in the dataset"
                    ))
                    .at(&data_dir)
                })
        })
        .collect::<Result<_>>()?;
    data.train = train;
    let cand_bytes = std::fs::read(candidates).map_err(|e| Error::io(candidates, e))?;
    let full_size = read_cameras_json(candidates)?;
    let cands: Vec<Camera> = full_size
        .iter()
        .map(|c| downscale_camera(c, cfg.resolution))
        .collect();
    if cands.is_empty() {
        return Err(Error::invalid("the view list is empty").at(candidates));
    }
    for (i, c) in cands.iter().enumerate() {
        if c.name.is_empty() || RESERVED_VIEW_NAMES.contains(&c.name.as_str()) {
            return Err(Error::invalid(format!(
                "candidate {i} has the name '{}', which is empty or reserved ({})",
                c.name,
                RESERVED_VIEW_NAMES.join(", ")
            ))
            .at(candidates));
        }
        if cands[..i].iter().any(|d| d.name == c.name) {
            return Err(
                Error::invalid(format!("candidate '{}' is listed twice", c.name)).at(candidates),
            );
        }
        c.validate().map_err(|e| e.at(candidates))?;
    }
    // A candidate the dataset's cameras.json does not list (a candidate family's view,
    // SPEC.md §20.7) brings its truth along when the dataset has its image: appended
    // after the listed views, in no split, so listed candidates change nothing.
    for c in &full_size {
        if !data.views.iter().any(|v| v.camera.name == c.name)
            && let Some(v) = crate::dataset::load_unlisted_view(&data_dir, c, &load_options(&cfg))?
        {
            data.views.push(v);
        }
    }
    let mut eval_idx = Vec::new();
    if let Some(e) = evaluation {
        for c in read_cameras_json(e)? {
            let i = data
                .views
                .iter()
                .position(|v| v.camera.name == c.name)
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "evaluation view '{}' has no ground truth in the dataset",
                        c.name
                    ))
                    .at(e)
                })?;
            if cands.iter().any(|k| k.name == c.name) || data.train.contains(&i) {
                return Err(Error::invalid(format!(
                    "evaluation view '{}' is also a candidate or training view",
                    c.name
                ))
                .at(e));
            }
            if data.views[i].depth.is_none() {
                return Err(Error::invalid(format!(
                    "evaluation view '{}' has no ground-truth depth (needed to split existing and extrapolated pixels)",
                    c.name
                ))
                .at(e));
            }
            eval_idx.push(i);
        }
    }
    let digest = inputs_digest(&data, &scene_sha256, &cands, &eval_idx, cfg.background);
    Ok(Inputs {
        run: run.to_path_buf(),
        scene,
        scene_iterations,
        scene_sha256,
        data,
        candidates: cands,
        candidates_sha256: sha256_hex(&cand_bytes),
        evaluation: eval_idx,
        background: cfg.background,
        digest,
    })
}
