//! Clips as the stages store and read them (`video_<k>/frame_<j>.exr`, `.depth.exr`,
//! `cameras.json`), their depth aligned to a training view (paper §3.3.1, Eq. 5–6; SPEC.md
//! §20.3), and their intermediate frames as supervision.

use super::PipelineConfig;
use super::artifacts::{load_depth, load_image, save_depth, save_image};
use super::depth::{apply_alignment, warp_depth};
use super::generators::Generators;
use super::recon::Supervision;
use super::rundir::StepWriter;
use crate::camera::Camera;
use crate::camera::inria::{cameras_json_string, read_cameras_json};
use crate::error::{Error, Result};
use crate::io::image::ImageF32;
use crate::io::write_text;
use crate::models::{DepthHint, Video};
use crate::rng::stage_seed;
use crate::warp::align::{Alignment, Frame, RansacConfig, Space, ransac};
use std::path::Path;

/// A clip as stored: `video_<k>/frame_<j>.exr` (+ `.depth.exr`), `video_<k>/cameras.json`.
pub struct StoredVideo {
    pub frames: Vec<ImageF32>,
    pub cameras: Vec<Camera>,
    /// Aligned metric depth per frame, when known.
    pub depths: Option<Vec<Vec<f32>>>,
}

pub fn save_video(
    w: &mut StepWriter,
    dir: &str,
    frames: &[ImageF32],
    cameras: &[Camera],
    depths: Option<&[Vec<f32>]>,
) -> Result<()> {
    for (j, f) in frames.iter().enumerate() {
        save_image(w, &format!("{dir}/frame_{j:02}"), f)?;
        if let Some(d) = depths {
            save_depth(w, &format!("{dir}/frame_{j:02}"), &d[j], f.width, f.height)?;
        }
    }
    let text = cameras_json_string(cameras);
    w.put(&format!("{dir}/cameras.json"), |p| write_text(p, &text))?;
    Ok(())
}

pub fn load_video(dir: &Path) -> Result<StoredVideo> {
    let cameras = read_cameras_json(&dir.join("cameras.json"))?;
    let mut frames = Vec::new();
    let mut depths = Vec::new();
    let mut all_depth = true;
    for (j, c) in cameras.iter().enumerate() {
        let s = format!("frame_{j:02}");
        frames.push(load_image(dir, &s)?);
        if dir.join(format!("{s}.depth.exr")).is_file() {
            depths.push(load_depth(dir, &s, c.width as usize, c.height as usize)?);
        } else {
            all_depth = false;
        }
    }
    Ok(StoredVideo {
        frames,
        cameras,
        depths: all_depth.then_some(depths),
    })
}

/// The start of [`align_clip`]'s error when the clip's depth admits no fit (too few valid
/// pixels, degenerate estimates): a caller with another depth to fall back on matches it.
const NO_ALIGNMENT: &str = "the clip's video depth admits no alignment";

/// DIBR-based video depth alignment (paper §3.3.1, Eq. 5–6) of one clip from a training
/// view (`start_depth`: its dense depth at `start_cam`) to a generated view (`end_cam`,
/// whose current depth `end_depth` is only a hint): video depth of every frame, aligned by
/// one RANSAC over all frames against the start depth DIBR-warped to every frame. Returns
/// the aligned metric depth of every frame (the last is the generated view's `D`), the
/// fit and its space. `view` names the generated view in the RANSAC seed.
#[allow(clippy::too_many_arguments)]
pub fn align_clip(
    config: &PipelineConfig,
    gens: &Generators,
    video: &Video,
    start_depth: &[f32],
    start_cam: &Camera,
    end_depth: &[f32],
    end_cam: &Camera,
    view: &str,
) -> Result<(Vec<Vec<f32>>, Alignment, Space)> {
    // Eq. 5's target: the start frame's depth warped to every frame.
    let targets: Vec<Vec<f32>> = video
        .cameras
        .iter()
        .map(|c| warp_depth(start_depth, start_cam, c))
        .collect::<Result<_>>()?;
    // What the caller knows of each frame, for estimators that extend known depth: the
    // start frame's warped depth, else the end keyframe's warped there. Only the former
    // is Eq. 5's target.
    let known: Vec<Vec<f32>> = video
        .cameras
        .iter()
        .zip(&targets)
        .map(|(c, t)| {
            let end = warp_depth(end_depth, end_cam, c)?;
            Ok(t.iter()
                .zip(&end)
                .map(|(&a, &b)| if a > 0.0 { a } else { b })
                .collect())
        })
        .collect::<Result<_>>()?;
    let hints: Vec<DepthHint> = known
        .iter()
        .map(|t| DepthHint {
            depth: t,
            mask: None,
        })
        .collect();
    let est = gens.video_depth(video, &hints)?;
    let space = config.align_space.unwrap_or(est[0].kind.space());
    let frames: Vec<Frame> = est
        .iter()
        .zip(&targets)
        .map(|(e, t)| Frame {
            estimate: &e.values,
            depth: t,
        })
        .collect();
    let a = ransac(
        &frames,
        space,
        &RansacConfig {
            threshold: config.ransac_threshold,
            iterations: config.ransac_iterations,
            seed: stage_seed(config.seed, &format!("ransac:{view}")),
            ..RansacConfig::default()
        },
    )
    .map_err(|e| Error::degenerate(format!("{NO_ALIGNMENT}: {}", e.message)))?;
    let depths = est.iter().map(|e| apply_alignment(e, &a, space)).collect();
    Ok((depths, a, space))
}

/// The intermediate frames of a stored clip (the end frames are views already).
pub fn video_supervision(dir: &Path) -> Result<Vec<Supervision>> {
    let v = load_video(dir)?;
    let n = v.frames.len();
    Ok((1..n.saturating_sub(1))
        .map(|j| Supervision {
            camera: v.cameras[j].clone(),
            image: v.frames[j].clone(),
            depth: v.depths.as_ref().map(|d| d[j].clone()),
            coverage: None,
        })
        .collect())
}
