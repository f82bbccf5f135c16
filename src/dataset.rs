//! Datasets: posed images (and optionally depth, a sparse point cloud and a split), from
//! three layouts (SPEC.md §14.4):
//!
//! - **unseen scenes** (`reference_data/scenes/<name>/`, SPEC.md §14.5): `cameras.json`,
//!   `images/<name>.png`, optional `depth/<name>.exr` (camera z, channel `Y`, 0 = none),
//!   `points3D.ply`, `split.json` (`train` / `heldout` name lists);
//! - **COLMAP**: `sparse/0/` (or `sparse/`) with `cameras`, `images`, `points3D` in text or
//!   binary, and `images/<name>`;
//! - **transforms.json**: nerfstudio's single file or NeRF-synthetic's
//!   `transforms_train.json` + `transforms_test.json`.
//!
//! Views are sorted by camera name (INRIA sorts by image name). The in-distribution test
//! split is INRIA's `--eval` rule — every `test_every`-th view of the training set
//! (`index % 8 == 0`) — unless the layout states its own test list (NeRF-synthetic). The
//! held-out half of a split.json is never trained on and never in `test`.

use crate::camera::Camera;
use crate::camera::colmap::read_colmap_model;
use crate::camera::inria::read_cameras_json;
use crate::camera::transforms::{frame_image_path, read_transforms_json};
use crate::error::{Error, Result};
use crate::gaussian::ply::{PointCloud, read_point_cloud};
use crate::io::image::{ImageF32, downscale, read_depth, read_rgb};
use std::path::{Path, PathBuf};

/// Which layout a dataset directory uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    Unseen,
    Colmap,
    Transforms,
}

/// One posed image.
#[derive(Clone, Debug)]
pub struct View {
    pub camera: Camera,
    /// RGB in `[0, 1]`, the camera's size.
    pub image: ImageF32,
    /// Camera-z depth per pixel (0 or non-finite = unknown), when the dataset has it.
    pub depth: Option<Vec<f32>>,
}

/// A loaded dataset.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub root: PathBuf,
    pub layout: Layout,
    pub views: Vec<View>,
    pub points: Option<PointCloud>,
    /// Indices into `views`.
    pub train: Vec<usize>,
    pub test: Vec<usize>,
    pub heldout: Vec<usize>,
}

/// How to load.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoadOptions {
    /// Integer downscale factor (INRIA `-r 1|2|4|8`); images are box-filtered.
    pub resolution: u32,
    /// Colour under transparent pixels of RGBA images.
    pub background: [f32; 3],
    /// INRIA's `llffhold`: every n-th training view goes to `test`; 0 = no test split.
    pub test_every: u32,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            resolution: 1,
            background: [0.0; 3],
            test_every: 8,
        }
    }
}

/// The split a caller asks for by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    Train,
    Test,
    Heldout,
}

impl std::str::FromStr for Split {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "train" => Ok(Split::Train),
            "test" => Ok(Split::Test),
            "heldout" => Ok(Split::Heldout),
            _ => Err(format!("unknown split '{s}' (train, test or heldout)")),
        }
    }
}

impl Dataset {
    pub fn split(&self, s: Split) -> &[usize] {
        match s {
            Split::Train => &self.train,
            Split::Test => &self.test,
            Split::Heldout => &self.heldout,
        }
    }

    /// Cameras of the training views.
    pub fn train_cameras(&self) -> Vec<Camera> {
        self.train
            .iter()
            .map(|&i| self.views[i].camera.clone())
            .collect()
    }

    /// INRIA's `cameras_extent`: 1.1 × the largest distance of a training camera centre
    /// from their mean (`getNerfppNorm`); 1.1 when there is a single camera.
    pub fn scene_extent(&self) -> f32 {
        let cams = self.train_cameras();
        if cams.is_empty() {
            return 1.1;
        }
        let n = cams.len() as f64;
        let mean = cams.iter().fold(glam::DVec3::ZERO, |a, c| a + c.center) / n;
        let radius = cams
            .iter()
            .map(|c| (c.center - mean).length())
            .fold(0.0, f64::max);
        let r = if radius > 0.0 { radius } else { 1.0 };
        (1.1 * r) as f32
    }
}

fn detect(root: &Path) -> Result<Layout> {
    if root.join("cameras.json").is_file() && root.join("images").is_dir() {
        Ok(Layout::Unseen)
    } else if root.join("sparse").is_dir() {
        Ok(Layout::Colmap)
    } else if root.join("transforms.json").is_file() || root.join("transforms_train.json").is_file()
    {
        Ok(Layout::Transforms)
    } else if !root.is_dir() {
        Err(Error::invalid(format!(
            "dataset {} is not a directory",
            root.display()
        )))
    } else {
        Err(Error::invalid(format!(
            "{} is not a dataset: expected cameras.json + images/ (unseen), sparse/ (COLMAP) or \
             transforms*.json",
            root.display()
        )))
    }
}

/// Scale a camera's intrinsics for an integer downscale (the image is cropped to
/// `floor(size / factor)`, so the principal point scales without offset).
pub fn downscale_camera(cam: &Camera, f: u32) -> Camera {
    let mut c = cam.clone();
    let fl = f as f64;
    c.width = cam.width / f;
    c.height = cam.height / f;
    c.fx /= fl;
    c.fy /= fl;
    c.cx /= fl;
    c.cy /= fl;
    c
}

/// Box-downscale a depth map; a block with any unknown depth is unknown (0).
fn downscale_depth(d: &[f32], w: usize, h: usize, f: usize) -> Vec<f32> {
    if f == 1 {
        return d.to_vec();
    }
    let (ow, oh) = (w / f, h / f);
    let mut out = vec![0f32; ow * oh];
    for y in 0..oh {
        for x in 0..ow {
            let mut s = 0f32;
            let mut ok = true;
            for dy in 0..f {
                for dx in 0..f {
                    let v = d[(y * f + dy) * w + x * f + dx];
                    ok &= v.is_finite() && v > 0.0;
                    s += v;
                }
            }
            out[y * ow + x] = if ok { s / (f * f) as f32 } else { 0.0 };
        }
    }
    out
}

fn load_view(
    cam: &Camera,
    image_path: &Path,
    depth_path: Option<&Path>,
    opts: &LoadOptions,
) -> Result<View> {
    let img = read_rgb(image_path, opts.background)?;
    if img.width != cam.width as usize || img.height != cam.height as usize {
        return Err(Error::invalid(format!(
            "image is {}x{} but camera '{}' is {}x{}",
            img.width, img.height, cam.name, cam.width, cam.height
        ))
        .at(image_path));
    }
    let depth = match depth_path {
        Some(p) if p.is_file() => Some(read_depth(p, img.width, img.height)?),
        _ => None,
    };
    let f = opts.resolution as usize;
    let (w, h) = (img.width, img.height);
    Ok(View {
        camera: downscale_camera(cam, opts.resolution),
        image: downscale(&img, f),
        depth: depth.map(|d| downscale_depth(&d, w, h, f)),
    })
}

/// A view of an unseen-layout dataset (SPEC.md §14) that its `cameras.json` does not list:
/// a candidate family's (SPEC.md §20.7), `images/<name>.png` with `depth/<name>.exr` when
/// present, loaded as [`load`] loads a listed view. Only a camera that one of the
/// dataset's `families/*.json` lists under that name with that very pose has it (a user's
/// camera of the same name elsewhere is not that image's truth); `None` otherwise, and for
/// a name that is not a plain file stem.
pub fn load_unlisted_view(root: &Path, cam: &Camera, opts: &LoadOptions) -> Result<Option<View>> {
    let plain =
        !cam.name.is_empty() && !cam.name.starts_with('.') && !cam.name.contains(['/', '\\']);
    let img = root.join("images").join(format!("{}.png", cam.name));
    if !plain || detect(root)? != Layout::Unseen || !img.is_file() || !in_a_family(root, cam)? {
        return Ok(None);
    }
    let depth = root.join("depth").join(format!("{}.exr", cam.name));
    load_view(cam, &img, Some(&depth), opts).map(Some)
}

/// Whether one of `root/families/*.json` lists `cam` (its name, size, intrinsics and pose).
fn in_a_family(root: &Path, cam: &Camera) -> Result<bool> {
    let Ok(entries) = std::fs::read_dir(root.join("families")) else {
        return Ok(false);
    };
    let mut files: Vec<std::path::PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .filter(|p| p.file_stem().is_some_and(|s| s != "meta"))
        .collect();
    files.sort();
    for f in files {
        if read_cameras_json(&f)?.iter().any(|c| c == cam) {
            return Ok(true);
        }
    }
    Ok(false)
}

fn names_in(v: &serde_json::Value, key: &str, path: &Path) -> Result<Vec<String>> {
    let list = v
        .get(key)
        .and_then(|x| x.as_array())
        .ok_or_else(|| Error::parse(path, format!("no \"{key}\" list")))?;
    list.iter()
        .map(|x| {
            x.as_str()
                .map(str::to_string)
                .ok_or_else(|| Error::parse(path, format!("\"{key}\" holds a non-string entry")))
        })
        .collect()
}

/// Every `every`-th index of `ids` (position % every == 0) → test, the rest → train.
fn holdout(ids: &[usize], every: u32) -> (Vec<usize>, Vec<usize>) {
    if every == 0 {
        return (ids.to_vec(), Vec::new());
    }
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for (k, &i) in ids.iter().enumerate() {
        if k % every as usize == 0 {
            test.push(i);
        } else {
            train.push(i);
        }
    }
    (train, test)
}

/// Load a dataset directory.
pub fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset> {
    if opts.resolution == 0 {
        return Err(Error::invalid("resolution factor must be at least 1"));
    }
    let layout = detect(root)?;
    let mut views = Vec::new();
    let mut points = None;
    let mut fixed_test: Option<Vec<String>> = None;
    let mut split_lists: Option<(Vec<String>, Vec<String>)> = None;
    match layout {
        Layout::Unseen => {
            let mut cams = read_cameras_json(&root.join("cameras.json"))?;
            cams.sort_by(|a, b| a.name.cmp(&b.name));
            for cam in &cams {
                let img = root.join("images").join(format!("{}.png", cam.name));
                let depth = root.join("depth").join(format!("{}.exr", cam.name));
                views.push(load_view(cam, &img, Some(&depth), opts)?);
            }
            let pts = root.join("points3D.ply");
            if pts.is_file() {
                points = Some(read_point_cloud(&pts)?);
            }
            let sp = root.join("split.json");
            if sp.is_file() {
                let text = std::fs::read(&sp).map_err(|e| Error::io(&sp, e))?;
                let v: serde_json::Value = serde_json::from_slice(&text)
                    .map_err(|e| Error::parse(&sp, format!("invalid JSON: {e}")))?;
                split_lists = Some((names_in(&v, "train", &sp)?, names_in(&v, "heldout", &sp)?));
            }
        }
        Layout::Colmap => {
            let sparse = if root.join("sparse/0").is_dir() {
                root.join("sparse/0")
            } else {
                root.join("sparse")
            };
            let model = read_colmap_model(&sparse)?;
            for cam in &model.cameras {
                let img = root.join("images").join(&cam.name);
                views.push(load_view(cam, &img, None, opts)?);
            }
            if !model.points.is_empty() {
                points = Some(PointCloud {
                    xyz: model
                        .points
                        .iter()
                        .map(|p| p.xyz.map(|v| v as f32))
                        .collect(),
                    rgb: model
                        .points
                        .iter()
                        .map(|p| p.rgb.map(|v| v as f32 / 255.0))
                        .collect(),
                });
            }
        }
        Layout::Transforms => {
            let mut files = Vec::new();
            if root.join("transforms_train.json").is_file() {
                files.push(root.join("transforms_train.json"));
                let t = root.join("transforms_test.json");
                if t.is_file() {
                    let cams = read_transforms_json(&t)?;
                    fixed_test = Some(cams.iter().map(|c| c.name.clone()).collect());
                    files.push(t);
                }
            } else {
                files.push(root.join("transforms.json"));
            }
            let mut cams = Vec::new();
            for f in &files {
                let dir = f.parent().unwrap_or(Path::new("."));
                for cam in read_transforms_json(f)? {
                    let img = frame_image_path(dir, &cam.name);
                    cams.push((cam, img));
                }
            }
            cams.sort_by(|a, b| a.0.name.cmp(&b.0.name));
            for (cam, img) in &cams {
                views.push(load_view(cam, img, None, opts)?);
            }
        }
    }
    for w in views.windows(2) {
        if w[0].camera.name == w[1].camera.name {
            return Err(Error::invalid(format!(
                "dataset {} has two views named '{}'",
                root.display(),
                w[0].camera.name
            )));
        }
    }
    let index_of = |name: &str| views.iter().position(|v| v.camera.name == name);
    let lookup = |names: &[String], what: &str| -> Result<Vec<usize>> {
        let mut ids: Vec<usize> = names
            .iter()
            .map(|n| {
                index_of(n).ok_or_else(|| {
                    Error::invalid(format!("{what} lists '{n}', which has no camera"))
                        .at(&root.join("split.json"))
                })
            })
            .collect::<Result<_>>()?;
        ids.sort_unstable();
        ids.dedup();
        Ok(ids)
    };
    let (train, test, heldout) = if let Some(test_names) = fixed_test {
        let test = lookup(&test_names, "transforms_test.json")?;
        let train = (0..views.len()).filter(|i| !test.contains(i)).collect();
        (train, test, Vec::new())
    } else if let Some((tr, ho)) = split_lists {
        let tr = lookup(&tr, "split.json \"train\"")?;
        let ho = lookup(&ho, "split.json \"heldout\"")?;
        if let Some(i) = tr.iter().find(|i| ho.contains(i)) {
            return Err(Error::invalid(format!(
                "view '{}' is in both halves",
                views[*i].camera.name
            ))
            .at(&root.join("split.json")));
        }
        let (train, test) = holdout(&tr, opts.test_every);
        (train, test, ho)
    } else {
        let all: Vec<usize> = (0..views.len()).collect();
        let (train, test) = holdout(&all, opts.test_every);
        (train, test, Vec::new())
    };
    if train.is_empty() {
        return Err(Error::invalid(format!(
            "dataset {} has no training views",
            root.display()
        )));
    }
    Ok(Dataset {
        root: root.to_path_buf(),
        layout,
        views,
        points,
        train,
        test,
        heldout,
    })
}
