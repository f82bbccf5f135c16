//! ONNX models through tract (SPEC.md §19.4) — the only module that imports tract.
//!
//! A model is described by a JSON *model card* next to (or pointing at) the `.onnx` file:
//! input and output names, tensor layout, the size policy, value range and normalization,
//! and what the output means. One adapter serves every slot ([`OnnxInpainter`],
//! [`OnnxDepth`], [`OnnxFixer`]); nothing is downloaded. tract runs single-threaded here, so
//! results do not depend on the rayon thread count.

use super::{
    ArtifactFixer, DepthEstimator, DepthHint, DepthKind, DepthMap, Inpainter, VideoDepthEstimator,
};
use crate::error::{Error, Result};
use crate::io::image::{Filter, ImageF32, resize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use tract_onnx::prelude::*;
use tract_onnx::tract_hir::infer::Factoid;

/// Tensor layout of image inputs and outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    Nchw,
    Nhwc,
}

/// How the model's input size is chosen from the image's.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(tag = "policy", rename_all = "snake_case")]
pub enum SizePolicy {
    /// The image's own size.
    Native,
    /// Always `width × height`.
    Fixed { width: usize, height: usize },
    /// Depth Anything's "lower bound": scale so both sides are ≥ `min_side` (aspect
    /// kept), each side rounded to the nearest multiple of `multiple`, rounded up instead
    /// when that falls below `min_side`.
    MultipleOf { multiple: usize, min_side: usize },
}

impl SizePolicy {
    /// The model input size for an image of `w × h`.
    pub fn apply(&self, w: usize, h: usize) -> (usize, usize) {
        match *self {
            SizePolicy::Native => (w, h),
            SizePolicy::Fixed { width, height } => (width, height),
            SizePolicy::MultipleOf { multiple, min_side } => {
                let scale = (min_side as f64 / w as f64).max(min_side as f64 / h as f64);
                let fit = |x: f64| {
                    let m = multiple as f64;
                    let mut y = (x / m).round_ties_even() * m;
                    if y < min_side as f64 {
                        y = (x / m).ceil() * m;
                    }
                    y as usize
                };
                (fit(w as f64 * scale), fit(h as f64 * scale))
            }
        }
    }
}

/// What the output holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OutputKind {
    Depth,
    Disparity,
    Image,
}

/// Input names of a card.
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    pub image: String,
    /// The mask input (inpainting): 1 channel, `mask_value` where to fill, 0 elsewhere.
    #[serde(default)]
    pub mask: Option<String>,
}

/// A model card (`CARD.json`).
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Card {
    /// The `.onnx` file, relative to the card.
    pub model: PathBuf,
    pub inputs: Inputs,
    pub output: String,
    pub layout: Layout,
    pub size: SizePolicy,
    /// Resampling to the model size; back to the image size is bilinear.
    pub resize: Filter,
    /// Image values `[0, 1]` are mapped linearly to this range, then `(v − mean)/std`.
    pub input_range: [f32; 2],
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
    pub output_kind: OutputKind,
    /// For image outputs: the model's value range, mapped back to `[0, 1]`.
    #[serde(default = "unit_range")]
    pub output_range: [f32; 2],
    #[serde(default = "one")]
    pub mask_value: f32,
}

fn unit_range() -> [f32; 2] {
    [0.0, 1.0]
}

fn one() -> f32 {
    1.0
}

type Plan = Arc<TypedRunnableModel<TypedModel>>;

/// A loaded model with its card; optimized plans are cached per input shape.
pub struct OnnxModel {
    card_path: PathBuf,
    model_path: PathBuf,
    /// `onnx:` + sha256 of the card's bytes + sha256 of the model's bytes.
    fingerprint: String,
    pub card: Card,
    model: InferenceModel,
    image_input: usize,
    mask_input: Option<usize>,
    plans: Mutex<HashMap<Vec<usize>, Plan>>,
}

fn tract_err(path: &Path, what: &str, e: impl std::fmt::Display) -> Error {
    Error::invalid(format!("{what}: {e}")).at(path)
}

impl OnnxModel {
    /// Read the card and the model, check the names and the input ranks.
    pub fn load(card_path: &Path) -> Result<OnnxModel> {
        let text = std::fs::read_to_string(card_path).map_err(|e| Error::io(card_path, e))?;
        let card: Card = serde_json::from_str(&text)
            .map_err(|e| Error::parse(card_path, format!("not a model card: {e}")))?;
        if card.mean.len() != card.std.len() || card.std.iter().any(|&s| s.is_nan() || s <= 0.0) {
            return Err(
                Error::invalid("mean and std must have the same length, std > 0").at(card_path),
            );
        }
        let model_path = card_path
            .parent()
            .unwrap_or(Path::new("."))
            .join(&card.model);
        if !model_path.is_file() {
            return Err(
                Error::invalid(format!("model file {} not found", model_path.display()))
                    .at(card_path),
            );
        }
        let mut model = tract_onnx::onnx()
            .model_for_path(&model_path)
            .map_err(|e| tract_err(&model_path, "not a readable ONNX model", format!("{e:#}")))?;
        let names: Vec<String> = model
            .input_outlets()
            .map_err(|e| tract_err(&model_path, "model inputs", e))?
            .iter()
            .map(|o| model.node(o.node).name.clone())
            .collect();
        let find = |n: &str| {
            names.iter().position(|m| m == n).ok_or_else(|| {
                Error::invalid(format!(
                    "the model has no input '{n}' (inputs: {})",
                    names.join(", ")
                ))
                .at(&model_path)
            })
        };
        let image_input = find(&card.inputs.image)?;
        let mask_input = card.inputs.mask.as_deref().map(find).transpose()?;
        for (ix, name) in std::iter::once((image_input, &card.inputs.image))
            .chain(mask_input.zip(card.inputs.mask.as_ref()))
        {
            let fact = model
                .input_fact(ix)
                .map_err(|e| tract_err(&model_path, "model inputs", e))?;
            if let Some(rank) = fact.shape.rank().concretize()
                && rank != 4
            {
                return Err(Error::invalid(format!(
                    "input '{name}' has rank {rank}; the card's {:?} layout needs rank 4",
                    card.layout
                ))
                .at(&model_path));
            }
        }
        model.set_output_names([&card.output]).map_err(|_| {
            Error::invalid(format!("the model has no output '{}'", card.output)).at(&model_path)
        })?;
        let model_bytes = std::fs::read(&model_path).map_err(|e| Error::io(&model_path, e))?;
        let fingerprint = format!(
            "onnx:{}:{}",
            crate::io::sha256_hex(text.as_bytes()),
            crate::io::sha256_hex(&model_bytes)
        );
        Ok(OnnxModel {
            card_path: card_path.to_path_buf(),
            model_path,
            fingerprint,
            card,
            model,
            image_input,
            mask_input,
            plans: Mutex::new(HashMap::new()),
        })
    }

    /// What identifies the model's behaviour: the hashes of its card and its weights.
    pub fn fingerprint(&self) -> &str {
        &self.fingerprint
    }

    /// The model input size for an image of `w × h` (SPEC.md §19.4).
    pub fn model_size(&self, w: usize, h: usize) -> (usize, usize) {
        self.card.size.apply(w, h)
    }

    fn plan(&self, shapes: &[Vec<usize>]) -> Result<Plan> {
        let key: Vec<usize> = shapes.iter().flatten().copied().collect();
        let mut cache = self.plans.lock().expect("plan cache");
        if let Some(p) = cache.get(&key) {
            return Ok(p.clone());
        }
        let mut m = self.model.clone();
        let mut ixs = vec![self.image_input];
        ixs.extend(self.mask_input);
        for (ix, shape) in ixs.iter().zip(shapes) {
            m = m
                .with_input_fact(*ix, f32::fact(shape).into())
                .map_err(|e| tract_err(&self.model_path, &format!("input shape {shape:?}"), e))?;
        }
        let plan = m
            .into_optimized()
            .and_then(|m| m.into_runnable())
            .map_err(|e| {
                tract_err(
                    &self.model_path,
                    "the model does not run on these input shapes",
                    format!("{e:#}"),
                )
            })?;
        let plan = Arc::new(plan);
        cache.insert(key, plan.clone());
        Ok(plan)
    }

    /// Run on raw tensors (shapes and row-major data), in the card's input order (image,
    /// then mask); returns the output's shape and values.
    pub fn run_tensors(&self, inputs: &[(Vec<usize>, Vec<f32>)]) -> Result<(Vec<usize>, Vec<f32>)> {
        let shapes: Vec<Vec<usize>> = inputs.iter().map(|(s, _)| s.clone()).collect();
        let plan = self.plan(&shapes)?;
        // The plan's inputs are in model order; put ours there.
        let mut order: Vec<(usize, usize)> = vec![(self.image_input, 0)];
        if let Some(m) = self.mask_input {
            order.push((m, 1));
        }
        order.sort_unstable();
        let mut tv = TVec::new();
        for (_, k) in order {
            let (shape, data) = &inputs[k];
            let t = Tensor::from_shape(shape, data)
                .map_err(|e| tract_err(&self.model_path, "input tensor", e))?;
            tv.push(t.into_tvalue());
        }
        let out = plan
            .run(tv)
            .map_err(|e| tract_err(&self.model_path, "inference failed", format!("{e:#}")))?;
        let t = out[0]
            .cast_to::<f32>()
            .map_err(|e| tract_err(&self.model_path, "output", e))?;
        let view = t
            .to_array_view::<f32>()
            .map_err(|e| tract_err(&self.model_path, "output", e))?;
        Ok((view.shape().to_vec(), view.iter().copied().collect()))
    }

    /// Image → the model's input tensor (resize, range, normalization, layout).
    fn image_tensor(&self, img: &ImageF32) -> Result<(Vec<usize>, Vec<f32>)> {
        let c = &self.card;
        if !c.mean.is_empty() && c.mean.len() != img.channels {
            return Err(Error::invalid(format!(
                "the card normalizes {} channels but the image has {}",
                c.mean.len(),
                img.channels
            ))
            .at(&self.card_path));
        }
        let (mw, mh) = self.model_size(img.width, img.height);
        let r = if (mw, mh) == (img.width, img.height) {
            img.clone()
        } else {
            resize(img, mw, mh, c.resize)?
        };
        let [lo, hi] = c.input_range;
        let ch = img.channels;
        let norm = |v: f32, k: usize| {
            let x = lo + v * (hi - lo);
            if c.mean.is_empty() {
                x
            } else {
                (x - c.mean[k]) / c.std[k]
            }
        };
        let t = to_layout(&r, c.layout, norm);
        debug_assert_eq!(t.1.len(), mw * mh * ch);
        Ok(t)
    }

    fn mask_tensor(&self, mask: &[bool], w: usize, h: usize) -> Result<(Vec<usize>, Vec<f32>)> {
        let (mw, mh) = self.model_size(w, h);
        let m = ImageF32::new(w, h, 1, mask.iter().map(|&b| b as u8 as f32).collect())?;
        // A resized mask is re-binarized: any coverage marks the pixel to fill.
        let r = if (mw, mh) == (w, h) {
            m
        } else {
            resize(&m, mw, mh, Filter::Bilinear)?
        };
        let v = self.card.mask_value;
        Ok(to_layout(&r, self.card.layout, |x, _| {
            if x > 0.0 { v } else { 0.0 }
        }))
    }

    /// Output tensor → a `channels`-channel image of the model size (leading 1-sized
    /// dimensions dropped; rank 2 = one channel).
    fn output_image(&self, shape: &[usize], data: Vec<f32>) -> Result<ImageF32> {
        let dims: Vec<usize> = {
            let mut d = shape.to_vec();
            while d.len() > 2 && d[0] == 1 {
                d.remove(0);
            }
            d
        };
        let bad = || {
            Error::invalid(format!(
                "output '{}' has shape {shape:?}, not an image in {:?} layout",
                self.card.output, self.card.layout
            ))
            .at(&self.model_path)
        };
        match (dims.len(), self.card.layout) {
            (2, _) => ImageF32::new(dims[1], dims[0], 1, data),
            (3, Layout::Nchw) => {
                let (c, h, w) = (dims[0], dims[1], dims[2]);
                let mut out = vec![0f32; c * h * w];
                for k in 0..c {
                    for p in 0..h * w {
                        out[p * c + k] = data[k * h * w + p];
                    }
                }
                ImageF32::new(w, h, c, out)
            }
            (3, Layout::Nhwc) => ImageF32::new(dims[1], dims[0], dims[2], data),
            _ => Err(bad()),
        }
    }

    /// Run on an image (and mask): the output as an image of the input's size.
    pub fn run_image(&self, img: &ImageF32, mask: Option<&[bool]>) -> Result<ImageF32> {
        let mut inputs = vec![self.image_tensor(img)?];
        match (self.mask_input, mask) {
            (Some(_), Some(m)) => inputs.push(self.mask_tensor(m, img.width, img.height)?),
            (Some(_), None) => {
                return Err(Error::invalid("this model needs a mask").at(&self.card_path));
            }
            (None, _) => {}
        }
        let (shape, data) = self.run_tensors(&inputs)?;
        if data.iter().any(|v| !v.is_finite()) {
            return Err(
                Error::invalid("the model produced NaN or infinite values").at(&self.model_path)
            );
        }
        let out = self.output_image(&shape, data)?;
        if (out.width, out.height) == (img.width, img.height) {
            Ok(out)
        } else {
            resize(&out, img.width, img.height, Filter::Bilinear)
        }
    }
}

/// An image as a 4-D tensor in `layout`, each value through `f(value, channel)`.
fn to_layout(
    img: &ImageF32,
    layout: Layout,
    f: impl Fn(f32, usize) -> f32,
) -> (Vec<usize>, Vec<f32>) {
    let (w, h, c) = (img.width, img.height, img.channels);
    match layout {
        Layout::Nhwc => (
            vec![1, h, w, c],
            img.data
                .iter()
                .enumerate()
                .map(|(i, &v)| f(v, i % c))
                .collect(),
        ),
        Layout::Nchw => {
            let mut out = vec![0f32; c * h * w];
            for p in 0..h * w {
                for k in 0..c {
                    out[k * h * w + p] = f(img.data[p * c + k], k);
                }
            }
            (vec![1, c, h, w], out)
        }
    }
}

fn expect_kind(m: &OnnxModel, kinds: &[OutputKind], slot: &str) -> Result<()> {
    if kinds.contains(&m.card.output_kind) {
        Ok(())
    } else {
        Err(Error::invalid(format!(
            "output_kind {:?} cannot serve the {slot} slot",
            m.card.output_kind
        ))
        .at(&m.card_path))
    }
}

/// Map an image output from the card's `output_range` to `[0, 1]`.
fn unit(m: &OnnxModel, mut img: ImageF32) -> ImageF32 {
    let [lo, hi] = m.card.output_range;
    for v in &mut img.data {
        *v = (*v - lo) / (hi - lo);
    }
    img
}

/// An ONNX inpainter (LaMa-style: image + mask → image). Known pixels are kept exactly;
/// the model's output is used only under the mask.
pub struct OnnxInpainter(pub OnnxModel);

impl OnnxInpainter {
    pub fn load(card: &Path) -> Result<Self> {
        let m = OnnxModel::load(card)?;
        expect_kind(&m, &[OutputKind::Image], "inpainting")?;
        if m.mask_input.is_none() {
            return Err(Error::invalid("an inpainting card needs inputs.mask").at(card));
        }
        Ok(OnnxInpainter(m))
    }
}

impl Inpainter for OnnxInpainter {
    fn name(&self) -> &str {
        "onnx"
    }
    fn fingerprint(&self) -> String {
        self.0.fingerprint().to_string()
    }
    fn inpaint(&self, image: &ImageF32, mask: &[bool]) -> Result<ImageF32> {
        if mask.len() != image.width * image.height {
            return Err(Error::invalid("the mask does not have the image's size"));
        }
        let generated = unit(&self.0, self.0.run_image(image, Some(mask))?);
        if generated.channels != image.channels {
            return Err(Error::invalid(format!(
                "the model returned {} channels for a {}-channel image",
                generated.channels, image.channels
            ))
            .at(&self.0.model_path));
        }
        let mut out = image.clone();
        let c = image.channels;
        for (p, &m) in mask.iter().enumerate() {
            if m {
                out.data[p * c..(p + 1) * c].copy_from_slice(&generated.data[p * c..(p + 1) * c]);
            }
        }
        Ok(out)
    }
}

/// An ONNX depth estimator (Depth Anything style: image → depth or disparity).
pub struct OnnxDepth(pub OnnxModel);

impl OnnxDepth {
    pub fn load(card: &Path) -> Result<Self> {
        let m = OnnxModel::load(card)?;
        expect_kind(&m, &[OutputKind::Depth, OutputKind::Disparity], "depth")?;
        Ok(OnnxDepth(m))
    }
}

impl DepthEstimator for OnnxDepth {
    fn name(&self) -> &str {
        "onnx"
    }
    fn fingerprint(&self) -> String {
        self.0.fingerprint().to_string()
    }
    fn estimate(&self, image: &ImageF32, _hint: Option<DepthHint>) -> Result<DepthMap> {
        let d = self.0.run_image(image, None)?;
        if d.channels != 1 {
            return Err(Error::invalid(format!(
                "a depth output must have 1 channel, got {}",
                d.channels
            ))
            .at(&self.0.model_path));
        }
        Ok(DepthMap {
            width: d.width,
            height: d.height,
            kind: match self.0.card.output_kind {
                OutputKind::Disparity => DepthKind::Disparity,
                _ => DepthKind::Depth,
            },
            values: d.data,
        })
    }
}

/// Frame by frame (an image model has no temporal consistency; the pipeline's
/// multi-frame RANSAC gives the clip one scale and shift, SPEC.md §17).
impl VideoDepthEstimator for OnnxDepth {
    fn name(&self) -> &str {
        "onnx"
    }
    fn fingerprint(&self) -> String {
        self.0.fingerprint().to_string()
    }
    fn estimate(&self, frames: &[ImageF32], _hints: Option<&[DepthHint]>) -> Result<Vec<DepthMap>> {
        frames
            .iter()
            .map(|f| DepthEstimator::estimate(self, f, None))
            .collect()
    }
}

/// An ONNX artifact fixer (render → image; the reference is not passed).
pub struct OnnxFixer(pub OnnxModel);

impl OnnxFixer {
    pub fn load(card: &Path) -> Result<Self> {
        let m = OnnxModel::load(card)?;
        expect_kind(&m, &[OutputKind::Image], "artifact removal")?;
        Ok(OnnxFixer(m))
    }
}

impl ArtifactFixer for OnnxFixer {
    fn name(&self) -> &str {
        "onnx"
    }
    fn fingerprint(&self) -> String {
        self.0.fingerprint().to_string()
    }
    fn fix(&self, render: &ImageF32, _reference: Option<&ImageF32>) -> Result<ImageF32> {
        Ok(unit(&self.0, self.0.run_image(render, None)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped cards parse, and Depth Anything's lower-bound policy gives the sizes its
    /// own transform gives (both sides ≥ 518, multiples of 14).
    #[test]
    fn shipped_cards_parse_and_size_policies() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/cards");
        for f in ["depth_anything_v2_small.json", "lama.json"] {
            let text = std::fs::read_to_string(root.join(f)).unwrap();
            let _: Card = serde_json::from_str(&text).unwrap();
        }
        let da = SizePolicy::MultipleOf {
            multiple: 14,
            min_side: 518,
        };
        assert_eq!(da.apply(640, 480), (686, 518));
        assert_eq!(da.apply(518, 518), (518, 518));
        assert_eq!(da.apply(160, 120), (686, 518));
        assert_eq!(da.apply(1024, 768), (686, 518));
        assert_eq!(da.apply(300, 900), (518, 1554));
        assert_eq!(SizePolicy::Native.apply(7, 5), (7, 5));
    }
}
