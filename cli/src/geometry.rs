//! Geometry commands: `unseen warp`, `unseen collide`, `unseen views` (SPEC.md §11, §16,
//! §18).

use clap::Args;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use unseen::camera::{find, inria};
use unseen::collide::frustum::{Outline, mean_range, write_obj};
use unseen::collide::gjk::{ConvexHull, proximity};
use unseen::collide::independent::select_regions;
use unseen::error::{Error, Result};
use unseen::io::image::{ImageF32, check_same_size, read_exr, read_png, write_exr, write_png};
use unseen::io::{create_dir_all, write_text};
use unseen::warp::dibr::{Footprint, WarpOptions, warp};

#[derive(Args)]
pub struct WarpArgs {
    /// Source image (PNG, 8-bit gray or RGB).
    #[arg(long)]
    image: PathBuf,
    /// Source depth (EXR, camera z, channel Y; 0/NaN/Inf = invalid).
    #[arg(long)]
    depth: PathBuf,
    /// Source camera name.
    #[arg(long)]
    from: String,
    /// Target camera name.
    #[arg(long)]
    to: String,
    /// Cameras (INRIA cameras.json).
    #[arg(long)]
    cameras: PathBuf,
    /// Output folder: warped.png, depth.exr, holes.png, warp.json.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, value_parser = crate::one_of(&Footprint::ALL, Footprint::name), default_value = "nearest")]
    footprint: Footprint,
    /// Crack closing radius (0 = off).
    #[arg(long, default_value_t = 0)]
    close_cracks: u32,
    /// Hole growing radius (0 = off).
    #[arg(long, default_value_t = 0)]
    grow_holes: u32,
    /// Relative depth band of one surface.
    #[arg(long, default_value_t = WarpOptions::default().depth_tolerance)]
    depth_tolerance: f32,
}

#[derive(Args)]
pub struct CollideArgs {
    /// First polyhedron: {"vertices": [[x, y, z], ...]} (their convex hull).
    a: PathBuf,
    /// Second polyhedron, same format.
    b: PathBuf,
    /// Print one JSON line {"intersect": bool, "distance": D}.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct ViewsArgs {
    /// Cameras (INRIA cameras.json).
    #[arg(long)]
    cameras: PathBuf,
    /// Candidate view names, comma-separated, in the greedy order.
    #[arg(long, value_delimiter = ',', required = true)]
    candidates: Vec<String>,
    /// Folder of inpainting masks `<name>.png` (non-zero = inpainted).
    #[arg(long)]
    masks: PathBuf,
    /// JSON {"<name>": [Dmin, Dmax]} or {"<name>": [[Dmin, Dmax], ...]} (one range per
    /// inpainting; averaged as paper Eq. 4).
    #[arg(long)]
    depth_ranges: PathBuf,
    /// Frustum outline: the mask's bounding box (the paper) or its convex hull.
    #[arg(long, value_parser = crate::one_of(&Outline::ALL, Outline::name), default_value = "bounding_box")]
    outline: Outline,
    /// Output folder: views.json, frustums.obj.
    #[arg(long)]
    out: PathBuf,
}

/// The inputs `unseen warp` and `unseen oracle warp` read: image, depth, the two cameras
/// and the options.
pub struct WarpInputs {
    pub image: ImageF32,
    pub depth: Vec<f32>,
    pub from: unseen::camera::Camera,
    pub to: unseen::camera::Camera,
    pub opts: WarpOptions,
}

impl WarpArgs {
    /// The output folder.
    pub fn out(&self) -> &Path {
        &self.out
    }

    /// Read and check the inputs.
    pub fn inputs(&self) -> Result<WarpInputs> {
        let a = self;
        let cams = inria::read_cameras_json(&a.cameras)?;
        let (from, to) = (
            find(&cams, &a.from, &a.cameras)?.clone(),
            find(&cams, &a.to, &a.cameras)?.clone(),
        );
        let image = read_png(&a.image)?;
        if (image.width, image.height) != (from.width as usize, from.height as usize) {
            return Err(Error::invalid(format!(
                "image is {}x{} but camera '{}' is {}x{}",
                image.width, image.height, from.name, from.width, from.height
            ))
            .at(&a.image));
        }
        let depth = read_exr(&a.depth, &["Y"])?;
        check_same_size(
            &a.depth,
            (depth.width, depth.height),
            &a.image,
            (image.width, image.height),
        )?;
        let opts = WarpOptions {
            footprint: a.footprint,
            depth_tolerance: a.depth_tolerance,
            close_cracks: a.close_cracks,
            grow_holes: a.grow_holes,
        };
        opts.validate()?;
        Ok(WarpInputs {
            image,
            depth: depth.data,
            from,
            to,
            opts,
        })
    }
}

pub fn run_warp(a: &WarpArgs) -> Result<()> {
    let WarpInputs {
        image,
        depth,
        from,
        to,
        opts,
    } = a.inputs()?;
    let (from, to) = (&from, &to);
    let w = warp(&image, &depth, from, to, &opts).map_err(|e| e.at(&a.image))?;
    let (tw, th) = (to.width as usize, to.height as usize);
    create_dir_all(&a.out)?;
    write_png(&a.out.join("warped.png"), &w.image)?;
    write_exr(
        &a.out.join("depth.exr"),
        &ImageF32::new(tw, th, 1, w.depth.clone())?,
    )?;
    let holes = w.holes.iter().map(|&h| if h { 1.0 } else { 0.0 }).collect();
    write_png(&a.out.join("holes.png"), &ImageF32::new(tw, th, 1, holes)?)?;
    let json = serde_json::json!({ "from": a.from, "to": a.to, "options": opts, "stats": w.stats });
    write_text(&a.out.join("warp.json"), &format!("{json:#}\n"))?;
    println!(
        "warped {} -> {}: {} hole pixels of {} ({} invalid source depths, {} cracks filled)",
        a.from,
        a.to,
        w.holes.iter().filter(|&&h| h).count(),
        tw * th,
        w.stats.invalid_depth,
        w.stats.cracks_filled
    );
    Ok(())
}

/// A polyhedron file `{"vertices": [[x, y, z], ...]}` as its convex hull.
pub fn read_hull(path: &Path) -> Result<ConvexHull> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        vertices: Vec<[f64; 3]>,
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let f: File = serde_json::from_str(&text).map_err(|e| Error::parse(path, format!("{e}")))?;
    ConvexHull::new(f.vertices.iter().map(|&v| v.into()).collect()).map_err(|e| e.at(path))
}

pub fn run_collide(a: &CollideArgs) -> Result<()> {
    let (ha, hb) = (read_hull(&a.a)?, read_hull(&a.b)?);
    let p = proximity(&ha, &hb)?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({"intersect": p.intersect, "distance": p.distance, "lower_bound": p.lower_bound})
        );
    } else {
        println!(
            "{} (distance in [{:e}, {:e}]; a lower bound at or below {:e} counts as intersecting; {} GJK iterations)",
            if p.intersect {
                "intersect"
            } else {
                "separated"
            },
            p.lower_bound,
            p.distance,
            p.touch_eps,
            p.iterations
        );
    }
    Ok(())
}

fn read_ranges(path: &Path) -> Result<BTreeMap<String, [f64; 2]>> {
    #[derive(serde::Deserialize)]
    #[serde(untagged)]
    enum Ranges {
        One([f64; 2]),
        Many(Vec<[f64; 2]>),
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let raw: BTreeMap<String, Ranges> = serde_json::from_str(&text).map_err(|e| {
        Error::parse(
            path,
            format!(
                "{e} (expected {{\"name\": [Dmin, Dmax]}} or {{\"name\": [[Dmin, Dmax], ...]}})"
            ),
        )
    })?;
    raw.into_iter()
        .map(|(k, v)| {
            let r = match v {
                Ranges::One(r) => r,
                Ranges::Many(rs) => mean_range(&rs).map_err(|e| e.at(path))?,
            };
            Ok((k, r))
        })
        .collect()
}

/// What `unseen views` and `unseen oracle views` read: the candidates' cameras in the
/// greedy order, their masks and their depth ranges.
pub struct ViewsInputs {
    pub cameras: Vec<unseen::camera::Camera>,
    pub masks: Vec<Vec<bool>>,
    pub ranges: Vec<[f64; 2]>,
}

impl ViewsArgs {
    /// The output folder.
    pub fn out(&self) -> &Path {
        &self.out
    }

    pub fn outline(&self) -> Outline {
        self.outline
    }

    /// Read and check the inputs.
    pub fn inputs(&self) -> Result<ViewsInputs> {
        let a = self;
        let cams = inria::read_cameras_json(&a.cameras)?;
        let ranges = read_ranges(&a.depth_ranges)?;
        let mut cand = Vec::new();
        let mut masks = Vec::new();
        let mut rs = Vec::new();
        for name in &a.candidates {
            let cam = find(&cams, name, &a.cameras)?;
            let path = a.masks.join(format!("{name}.png"));
            let m = read_png(&path)?;
            if (m.width, m.height) != (cam.width as usize, cam.height as usize) {
                return Err(Error::invalid(format!(
                    "mask is {}x{} but camera '{name}' is {}x{}",
                    m.width, m.height, cam.width, cam.height
                ))
                .at(&path));
            }
            masks.push(
                m.data
                    .chunks(m.channels)
                    .map(|c| c.iter().any(|&v| v > 0.0))
                    .collect::<Vec<bool>>(),
            );
            rs.push(*ranges.get(name).ok_or_else(|| {
                Error::invalid(format!("no depth range for '{name}'")).at(&a.depth_ranges)
            })?);
            cand.push(cam.clone());
        }
        Ok(ViewsInputs {
            cameras: cand,
            masks,
            ranges: rs,
        })
    }
}

pub fn run_views(a: &ViewsArgs) -> Result<()> {
    let outline = a.outline;
    let ViewsInputs {
        cameras,
        masks,
        ranges: rs,
    } = a.inputs()?;
    let cand: Vec<&unseen::camera::Camera> = cameras.iter().collect();
    let ranges: BTreeMap<&str, [f64; 2]> = cameras
        .iter()
        .zip(&rs)
        .map(|(c, r)| (c.name.as_str(), *r))
        .collect();
    let (polys, sel) =
        select_regions(&cand, &masks, &rs, outline, None).map_err(|e| e.at(&a.masks))?;
    let names =
        |v: &[usize]| -> Vec<&str> { v.iter().map(|&i| a.candidates[i].as_str()).collect() };
    let pairs = |v: &[(usize, usize)]| -> Vec<[&str; 2]> {
        v.iter()
            .map(|&(i, j)| [a.candidates[i].as_str(), a.candidates[j].as_str()])
            .collect()
    };
    let frustums: Vec<serde_json::Value> = polys
        .iter()
        .map(|p| {
            serde_json::json!({
                "name": p.name,
                "vertices": p.vertices.iter().map(|v| [v.x, v.y, v.z]).collect::<Vec<_>>(),
                "depth_range": ranges[p.name.as_str()],
            })
        })
        .collect();
    let json = serde_json::json!({
        "candidates": a.candidates,
        "outline": outline.name(),
        "collisions": pairs(&sel.edges),
        "independent": names(&sel.independent),
        "trajectory": names(&sel.trajectory),
        "gaps": pairs(&sel.gaps),
        "frustums": frustums,
    });
    create_dir_all(&a.out)?;
    write_text(&a.out.join("views.json"), &format!("{json:#}\n"))?;
    write_obj(&a.out.join("frustums.obj"), &polys)?;
    println!(
        "{} candidates, {} collisions, {} independent: {}",
        a.candidates.len(),
        sel.edges.len(),
        sel.independent.len(),
        names(&sel.trajectory).join(" -> ")
    );
    Ok(())
}
