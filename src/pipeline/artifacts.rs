//! The files a pipeline step writes and the next one reads: images (EXR for the exact
//! floats, PNG for people), depth maps, masks, scenes (INRIA PLY) and JSON records, named
//! by [`stem`] of a camera name (SPEC.md §20).

use super::rundir::{StepDone, StepWriter};
use crate::error::{Error, Result};
use crate::gaussian::Gaussians;
use crate::gaussian::ply::{ply_bytes, read_ply};
use crate::io::image::{ImageF32, read_exr, read_png, write_exr, write_png};
use crate::io::write_atomic;
use std::io::Write;
use std::path::Path;

/// `stem.exr` (exact floats, read downstream) and `stem.png` (for people).
pub(crate) fn save_image(w: &mut StepWriter, stem: &str, img: &ImageF32) -> Result<()> {
    w.put(&format!("{stem}.exr"), |p| write_exr(p, img))?;
    w.put(&format!("{stem}.png"), |p| write_png(p, img))?;
    Ok(())
}

pub(crate) fn load_image(dir: &Path, stem: &str) -> Result<ImageF32> {
    read_exr(&dir.join(format!("{stem}.exr")), &["R", "G", "B"])
}

/// `stem.depth.exr` (camera z, channel Y).
pub(crate) fn save_depth(
    w: &mut StepWriter,
    stem: &str,
    depth: &[f32],
    width: usize,
    height: usize,
) -> Result<()> {
    let img = ImageF32::new(width, height, 1, depth.to_vec())?;
    w.put(&format!("{stem}.depth.exr"), |p| write_exr(p, &img))?;
    Ok(())
}

pub(crate) fn load_depth(dir: &Path, stem: &str, width: usize, height: usize) -> Result<Vec<f32>> {
    crate::io::image::read_depth(&dir.join(format!("{stem}.depth.exr")), width, height)
}

/// `stem.mask.png` (white = true; 8-bit, exact for booleans).
pub(crate) fn save_mask(
    w: &mut StepWriter,
    stem: &str,
    mask: &[bool],
    width: usize,
    height: usize,
) -> Result<()> {
    let img = ImageF32::new(
        width,
        height,
        1,
        mask.iter().map(|&m| if m { 1.0 } else { 0.0 }).collect(),
    )?;
    w.put(&format!("{stem}.mask.png"), |p| write_png(p, &img))?;
    Ok(())
}

pub(crate) fn load_mask(dir: &Path, stem: &str) -> Result<Vec<bool>> {
    let img = read_png(&dir.join(format!("{stem}.mask.png")))?;
    Ok(img.data.chunks(img.channels).map(|c| c[0] > 0.5).collect())
}

/// `rel` as an INRIA PLY.
pub(crate) fn save_scene(w: &mut StepWriter, rel: &str, g: &Gaussians) -> Result<()> {
    let bytes = ply_bytes(g)?;
    w.put(rel, |p| write_atomic(p, |f| f.write_all(&bytes)))?;
    Ok(())
}

pub(crate) fn load_scene(dir: &Path, rel: &str) -> Result<Gaussians> {
    Ok(read_ply(&dir.join(rel))?.0)
}

pub(crate) fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let b = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_slice(&b).map_err(|e| Error::parse(path, format!("invalid JSON: {e}")))
}

/// The folder or file stem of a camera name in a run directory: ASCII letters, digits,
/// `_` and `-` as they are, every other byte as `%XX` — injective, so two views never share
/// a file, and never `.`, `..` or a path separator.
pub fn stem(name: &str) -> String {
    let mut s = String::with_capacity(name.len());
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || b == b'_' || b == b'-' {
            s.push(b as char);
        } else {
            s.push_str(&format!("%{b:02X}"));
        }
    }
    s
}

/// The scene of a finished reconstruction step.
pub(crate) fn scene_of(step: &StepDone) -> Result<Gaussians> {
    load_scene(&step.dir, "scene.ply")
}
