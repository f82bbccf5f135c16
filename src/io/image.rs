//! PNG (8-bit) and OpenEXR (32-bit float, ZIP-compressed) images.
//!
//! Images in memory are row-major `f32`, `channels` interleaved values per pixel.

use super::write_atomic;
use crate::error::{Error as UError, Result};
use std::path::Path;

/// A float image: `height` rows of `width` pixels of `channels` values.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageF32 {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl ImageF32 {
    pub fn new(width: usize, height: usize, channels: usize, data: Vec<f32>) -> Result<Self> {
        if data.len() != width * height * channels {
            return Err(UError::invalid(format!(
                "image data has {} values, {width}x{height}x{channels} needs {}",
                data.len(),
                width * height * channels
            )));
        }
        Ok(ImageF32 {
            width,
            height,
            channels,
            data,
        })
    }
}

/// Quantize `[0, 1]` to 8 bits: clamp, then round half up (`floor(v·255 + 0.5)`).
/// NaN becomes 0.
pub fn to_u8(v: f32) -> u8 {
    let v = if v > 0.0 { v } else { 0.0 };
    let v = if v < 1.0 { v } else { 1.0 };
    (v * 255.0 + 0.5).floor() as u8
}

/// Write an 8-bit PNG (1 or 3 channels) from values in `[0, 1]` (clamped).
pub fn write_png(path: &Path, img: &ImageF32) -> Result<()> {
    let color = match img.channels {
        1 => image::ExtendedColorType::L8,
        3 => image::ExtendedColorType::Rgb8,
        4 => image::ExtendedColorType::Rgba8,
        c => return Err(UError::invalid(format!("cannot write a {c}-channel PNG")).at(path)),
    };
    let bytes: Vec<u8> = img.data.iter().map(|&v| to_u8(v)).collect();
    write_atomic(path, |w| {
        use image::ImageEncoder;
        image::codecs::png::PngEncoder::new(w)
            .write_image(&bytes, img.width as u32, img.height as u32, color)
            .map_err(std::io::Error::other)
    })
}

/// Read a PNG (or any format the `image` crate decodes) as RGB or gray floats in `[0, 1]`.
pub fn read_png(path: &Path) -> Result<ImageF32> {
    let img =
        image::open(path).map_err(|e| UError::parse(path, format!("cannot read image: {e}")))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (channels, raw) = if img.color().channel_count() == 1 {
        (1, img.into_luma8().into_raw())
    } else {
        (3, img.into_rgb8().into_raw())
    };
    ImageF32::new(
        w,
        h,
        channels,
        raw.into_iter().map(|b| b as f32 / 255.0).collect(),
    )
}

/// Read an 8- or 16-bit image as RGB floats in `[0, 1]`: gray is replicated, and an alpha
/// channel is composited over `background` (`rgb·a + bg·(1 − a)`, INRIA's handling of
/// NeRF-synthetic RGBA images).
pub fn read_rgb(path: &Path, background: [f32; 3]) -> Result<ImageF32> {
    let img =
        image::open(path).map_err(|e| UError::parse(path, format!("cannot read image: {e}")))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let has_alpha = img.color().has_alpha();
    let rgba: Vec<f32> = if img.color().bytes_per_pixel() / img.color().channel_count() > 1 {
        let v = img.into_rgba16().into_raw();
        v.into_iter().map(|x| x as f32 / 65535.0).collect()
    } else {
        let v = img.into_rgba8().into_raw();
        v.into_iter().map(|x| x as f32 / 255.0).collect()
    };
    let mut data = Vec::with_capacity(w * h * 3);
    for px in rgba.chunks_exact(4) {
        let a = if has_alpha { px[3] } else { 1.0 };
        for c in 0..3 {
            data.push(if has_alpha {
                px[c] * a + background[c] * (1.0 - a)
            } else {
                px[c]
            });
        }
    }
    ImageF32::new(w, h, 3, data)
}

/// Downscale by an integer `factor` with a box filter (the mean of each `factor × factor`
/// block, summed in row-major order in f32); a remainder at the right and bottom is
/// cropped.
pub fn downscale(img: &ImageF32, factor: usize) -> ImageF32 {
    assert!(factor >= 1);
    if factor == 1 {
        return img.clone();
    }
    let (w, h, c) = (img.width / factor, img.height / factor, img.channels);
    let inv = 1.0 / (factor * factor) as f32;
    let mut data = vec![0f32; w * h * c];
    for y in 0..h {
        for x in 0..w {
            for ch in 0..c {
                let mut s = 0f32;
                for dy in 0..factor {
                    for dx in 0..factor {
                        let p = (y * factor + dy) * img.width + x * factor + dx;
                        s += img.data[p * c + ch];
                    }
                }
                data[(y * w + x) * c + ch] = s * inv;
            }
        }
    }
    ImageF32 {
        width: w,
        height: h,
        channels: c,
        data,
    }
}

/// Interpolation of [`resize`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Filter {
    /// Bilinear with half-pixel centres (OpenCV `INTER_LINEAR`, PyTorch
    /// `align_corners=False`).
    Bilinear,
    /// Bicubic, Keys `a = −0.75` (OpenCV `INTER_CUBIC`), half-pixel centres, edge pixels
    /// replicated.
    Bicubic,
}

/// Per output coordinate: the first source index and the tap weights (2 or 4 taps),
/// source indices clamped to the image (f32, as OpenCV's float path).
fn taps(src: usize, dst: usize, filter: Filter) -> Vec<([usize; 4], [f32; 4])> {
    let scale = src as f64 / dst as f64;
    (0..dst)
        .map(|d| {
            let f = (d as f64 + 0.5) * scale - 0.5;
            let i = f.floor();
            let t = (f - i) as f32;
            let i = i as i64;
            let clamp = |k: i64| k.clamp(0, src as i64 - 1) as usize;
            match filter {
                Filter::Bilinear => {
                    // OpenCV: left of the first centre / right of the last one is the
                    // edge pixel itself.
                    let (i, t) = if i < 0 {
                        (0, 0.0)
                    } else if i >= src as i64 - 1 {
                        (src as i64 - 1, 0.0)
                    } else {
                        (i, t)
                    };
                    ([clamp(i), clamp(i + 1), 0, 0], [1.0 - t, t, 0.0, 0.0])
                }
                Filter::Bicubic => {
                    const A: f32 = -0.75;
                    let w0 =
                        ((A * (t + 1.0) - 5.0 * A) * (t + 1.0) + 8.0 * A) * (t + 1.0) - 4.0 * A;
                    let w1 = ((A + 2.0) * t - (A + 3.0)) * t * t + 1.0;
                    let w2 = ((A + 2.0) * (1.0 - t) - (A + 3.0)) * (1.0 - t) * (1.0 - t) + 1.0;
                    let w3 = 1.0 - w0 - w1 - w2;
                    (
                        [clamp(i - 1), clamp(i), clamp(i + 1), clamp(i + 2)],
                        [w0, w1, w2, w3],
                    )
                }
            }
        })
        .collect()
}

/// Resize to `width × height`: separable, horizontal pass then vertical, in f32.
pub fn resize(img: &ImageF32, width: usize, height: usize, filter: Filter) -> Result<ImageF32> {
    if width == 0 || height == 0 || img.width == 0 || img.height == 0 {
        return Err(UError::invalid("resize needs non-empty images"));
    }
    let c = img.channels;
    let n = match filter {
        Filter::Bilinear => 2,
        Filter::Bicubic => 4,
    };
    let tx = taps(img.width, width, filter);
    let ty = taps(img.height, height, filter);
    let mut rows = vec![0f32; img.height * width * c];
    for y in 0..img.height {
        for (x, (ix, wx)) in tx.iter().enumerate() {
            for ch in 0..c {
                let mut v = 0f32;
                for k in 0..n {
                    v += img.data[(y * img.width + ix[k]) * c + ch] * wx[k];
                }
                rows[(y * width + x) * c + ch] = v;
            }
        }
    }
    let mut data = vec![0f32; width * height * c];
    for (y, (iy, wy)) in ty.iter().enumerate() {
        for x in 0..width {
            for ch in 0..c {
                let mut v = 0f32;
                for k in 0..n {
                    v += rows[(iy[k] * width + x) * c + ch] * wy[k];
                }
                data[(y * width + x) * c + ch] = v;
            }
        }
    }
    ImageF32::new(width, height, c, data)
}

/// Write a float EXR (ZIP compression). Channel names: 1 → `Y`, 3 → `R G B`,
/// 4 → `R G B A`; other counts are named `C0, C1, ...`.
pub fn write_exr(path: &Path, img: &ImageF32) -> Result<()> {
    use exr::prelude::*;
    let names: Vec<String> = match img.channels {
        1 => vec!["Y".into()],
        3 => vec!["R".into(), "G".into(), "B".into()],
        4 => vec!["R".into(), "G".into(), "B".into(), "A".into()],
        c => (0..c).map(|k| format!("C{k}")).collect(),
    };
    let (w, h, c) = (img.width, img.height, img.channels);
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = names
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let samples: Vec<f32> = (0..w * h).map(|p| img.data[p * c + k]).collect();
            AnyChannel::new(n.as_str(), FlatSamples::F32(samples))
        })
        .collect();
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding {
            compression: Compression::ZIP16,
            ..Encoding::default()
        },
        AnyChannels::sort(channels),
    );
    let image = Image::from_layer(layer);
    // Sequential writing: the parallel writer may order blocks by completion, so the bytes
    // would depend on the thread count.
    super::write_atomic(path, |w| {
        image
            .write()
            .non_parallel()
            .to_buffered(w)
            .map_err(|e| std::io::Error::other(format!("cannot write EXR: {e}")))
    })
}

/// `path`, of `size`, belongs to the image `image` of `image_size` and must have its size:
/// the error names both files, since either may be the wrong one.
pub fn check_same_size(
    path: &Path,
    size: (usize, usize),
    image: &Path,
    image_size: (usize, usize),
) -> Result<()> {
    if size == image_size {
        return Ok(());
    }
    Err(UError::invalid(format!(
        "{}x{}, but the image {} is {}x{}",
        size.0,
        size.1,
        image.display(),
        image_size.0,
        image_size.1
    ))
    .at(path))
}

/// Read a depth map (EXR channel `Y`) that must be `width × height` (the size of the image
/// it belongs to); a size mismatch is an error naming the file.
pub fn read_depth(path: &Path, width: usize, height: usize) -> Result<Vec<f32>> {
    // The size is known: a header that declares another is refused before the decoder
    // allocates what it declares (up to 1 GiB for a few hundred bytes of PIZ or B44
    // header otherwise; found by the `run_readers` fuzz target).
    let declared = exr_size(path)?;
    if declared != (width, height) {
        return Err(UError::invalid(format!(
            "depth is {}x{} but the image is {width}x{height}",
            declared.0, declared.1
        ))
        .at(path));
    }
    let d = read_exr(path, &["Y"])?;
    if (d.width, d.height) != (width, height) {
        return Err(UError::invalid(format!(
            "depth is {}x{} but the image is {width}x{height}",
            d.width, d.height
        ))
        .at(path));
    }
    Ok(d.data)
}

/// Refuse an EXR whose declared pixels need more memory than its file can hold (SPEC.md
/// §10), from the header alone, before the decoder allocates them: the samples' bytes may
/// be at most the file size times the compression's largest ratio (none 1, RLE 64 — a
/// 128-byte run in 2 bytes —, ZIP 1032, deflate's limit, PXR24 1376 = 1032·4/3), plus
/// 64 KiB; for the
/// other compressions, whose ratio has no small bound, at most 1 GiB.
fn check_exr_size(path: &Path) -> Result<()> {
    use exr::compression::Compression as C;
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| UError::parse(path, format!("cannot read EXR: {e}")))?;
    let file = std::fs::metadata(path)
        .map_err(|e| UError::io(path, e))?
        .len() as u128;
    for h in &meta.headers {
        let (w, ht) = (h.layer_size.width() as u128, h.layer_size.height() as u128);
        let bytes: u128 = h
            .channels
            .list
            .iter()
            .map(|c| {
                let (sx, sy) = (c.sampling.x().max(1) as u128, c.sampling.y().max(1) as u128);
                w.div_ceil(sx) * ht.div_ceil(sy) * c.sample_type.bytes_per_sample() as u128
            })
            .sum();
        let limit = match h.compression {
            C::Uncompressed => file + (64 << 10),
            C::RLE => 64 * file + (64 << 10),
            C::ZIP1 | C::ZIP16 => 1032 * file + (64 << 10),
            // Deflate over 24 of every 32 bits of a float sample.
            C::PXR24 => 1376 * file + (64 << 10),
            _ => 1 << 30,
        };
        if bytes > limit {
            return Err(UError::parse(
                path,
                format!(
                    "the header declares {w}x{ht} pixels ({bytes} bytes of samples), more than \
                     a {file}-byte file compressed with {:?} can hold",
                    h.compression
                ),
            ));
        }
    }
    Ok(())
}

/// The size of an EXR's first valid layer at its largest resolution level, from the header
/// alone (what [`read_exr`] would return).
fn exr_size(path: &Path) -> Result<(usize, usize)> {
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| UError::parse(path, format!("cannot read EXR: {e}")))?;
    let h = meta
        .headers
        .iter()
        .find(|h| !h.deep)
        .ok_or_else(|| UError::parse(path, "cannot read EXR: no flat layer"))?;
    Ok((h.layer_size.width(), h.layer_size.height()))
}

/// Read the first layer of an EXR as float channels, in the order of `names`
/// (e.g. `["R","G","B"]` or `["Y"]`). Missing channels are an error naming them.
pub fn read_exr(path: &Path, names: &[&str]) -> Result<ImageF32> {
    use exr::prelude::*;
    check_exr_size(path)?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| UError::parse(path, format!("cannot read EXR: {e}")))?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let mut data = vec![0f32; w * h * names.len()];
    for (k, name) in names.iter().enumerate() {
        let ch = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == *name)
            .ok_or_else(|| UError::parse(path, format!("EXR has no channel '{name}'")))?;
        for (p, v) in ch.sample_data.values_as_f32().enumerate() {
            data[p * names.len() + k] = v;
        }
    }
    ImageF32::new(w, h, names.len(), data)
}
