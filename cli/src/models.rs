//! Model-slot commands: `unseen inpaint`, `unseen depth` (SPEC.md §19.5).

use clap::Args;
use std::path::{Path, PathBuf};
use unseen::error::Result;
use unseen::io::image::{
    ImageF32, check_same_size, read_exr, read_png, to_u8, write_exr, write_png,
};
use unseen::models::{
    DepthHint, DepthModel, InpaintDefault, InpaintModel, Model, depth_estimator, inpainter,
};

#[derive(Args)]
pub struct InpaintArgs {
    /// Image (PNG, 8-bit gray or RGB).
    image: PathBuf,
    /// Mask (PNG; non-zero pixels are filled, as in OpenCV).
    mask: PathBuf,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// `telea` or `onnx:CARD.json`.
    #[arg(long, default_value = "telea")]
    method: InpaintModel,
    /// Telea radius (OpenCV's `inpaintRadius`).
    #[arg(long, default_value_t = 3.0)]
    radius: f64,
}

#[derive(Args)]
pub struct DepthArgs {
    /// Image (PNG).
    image: PathBuf,
    /// Output EXR (channel Y).
    #[arg(long)]
    out: PathBuf,
    /// `depth-fill` or `onnx:CARD.json`.
    #[arg(long, default_value = "depth-fill")]
    method: DepthModel,
    /// Known depth (EXR, channel Y; ≤ 0 or not finite = unknown), for `depth-fill`.
    #[arg(long)]
    hint: Option<PathBuf>,
    /// Pixels of the hint to treat as unknown (PNG, non-zero).
    #[arg(long)]
    hint_mask: Option<PathBuf>,
}

/// A mask (non-zero = true) of `image`'s size.
fn read_mask(path: &Path, image: &Path, img: &ImageF32) -> Result<Vec<bool>> {
    let m = read_png(path)?;
    check_same_size(path, (m.width, m.height), image, (img.width, img.height))?;
    Ok(m.data
        .chunks(m.channels)
        .map(|c| c.iter().any(|&v| v > 0.0))
        .collect())
}

pub fn run_inpaint(a: &InpaintArgs) -> Result<()> {
    let img = read_png(&a.image)?;
    let mask = read_mask(&a.mask, &a.image, &img)?;
    let out = if a.method == Model::Classical(InpaintDefault::Telea) {
        // 8-bit in, 8-bit arithmetic: the same values as cv2.inpaint (SPEC.md §19.1).
        let bytes: Vec<u8> = img.data.iter().map(|&v| to_u8(v)).collect();
        let r = unseen::models::telea::inpaint(
            &bytes,
            img.width,
            img.height,
            img.channels,
            &mask,
            a.radius,
        )
        .map_err(|e| e.at(&a.image))?;
        ImageF32::new(
            img.width,
            img.height,
            img.channels,
            r.iter().map(|&b| b as f32 / 255.0).collect(),
        )?
    } else {
        inpainter(&a.method)?
            .inpaint(&img, &mask)
            .map_err(|e| e.at(&a.image))?
    };
    write_png(&a.out, &out)?;
    println!(
        "inpainted {} pixels of {} with {}",
        mask.iter().filter(|&&m| m).count(),
        a.image.display(),
        a.method
    );
    Ok(())
}

pub fn run_depth(a: &DepthArgs) -> Result<()> {
    let img = read_png(&a.image)?;
    let est = depth_estimator(&a.method)?;
    let hint = match &a.hint {
        Some(p) => {
            let d = read_exr(p, &["Y"])?;
            check_same_size(p, (d.width, d.height), &a.image, (img.width, img.height))?;
            Some(d.data)
        }
        None => None,
    };
    let mask = match &a.hint_mask {
        Some(p) => Some(read_mask(p, &a.image, &img)?),
        None => None,
    };
    let d = est
        .estimate(
            &img,
            hint.as_deref().map(|depth| DepthHint {
                depth,
                mask: mask.as_deref(),
            }),
        )
        .map_err(|e| e.at(&a.image))?;
    write_exr(&a.out, &ImageF32::new(d.width, d.height, 1, d.values)?)?;
    println!(
        "{} of {} ({}x{}) -> {}",
        match d.kind {
            unseen::models::DepthKind::Depth => "depth",
            unseen::models::DepthKind::Disparity => "disparity",
        },
        a.image.display(),
        d.width,
        d.height,
        a.out.display()
    );
    Ok(())
}
