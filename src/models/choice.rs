//! Which model fills a slot, as a value: one of the slot's classical defaults, or an ONNX
//! model named by its card. Parsed once from the slot's text (`telea`, `onnx:CARD.json`)
//! where a configuration enters; written back as the same text.

use crate::error::{Error, Result};
use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// The classical defaults of one slot (built by `defaults!`).
pub trait Defaults: Copy + fmt::Debug + 'static {
    /// The slot, as errors name it ("inpainter").
    const SLOT: &'static str;
    /// Every default, in the order errors list them.
    const ALL: &'static [Self];
    /// Whether the slot takes ONNX models.
    const ONNX: bool;
    /// The default's name in a configuration.
    fn name(self) -> &'static str;
}

/// A slot's model: a classical default or an ONNX model given by its card. (The video slot
/// takes no ONNX model: its text is refused when parsed, and a `VideoModel::Onnx` built in
/// code is refused when the slot is made.)
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Model<C> {
    Classical(C),
    /// The card (`onnx:CARD.json` in a configuration).
    Onnx(PathBuf),
}

/// The prefix of an ONNX model's card in a configuration.
const ONNX_PREFIX: &str = "onnx:";

impl<C: Defaults> FromStr for Model<C> {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        if C::ONNX
            && let Some(card) = s.strip_prefix(ONNX_PREFIX)
        {
            return Ok(Model::Onnx(PathBuf::from(card)));
        }
        if let Some(&c) = C::ALL.iter().find(|c| c.name() == s) {
            return Ok(Model::Classical(c));
        }
        let known: Vec<&str> = C::ALL.iter().map(|c| c.name()).collect();
        let onnx = if C::ONNX { ", or onnx:CARD.json" } else { "" };
        Err(Error::invalid(format!(
            "unknown {} '{s}' (known: {}{onnx})",
            C::SLOT,
            known.join(", ")
        )))
    }
}

impl<C: Defaults> fmt::Display for Model<C> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Model::Classical(c) => f.write_str(c.name()),
            Model::Onnx(card) => write!(f, "{ONNX_PREFIX}{}", card.display()),
        }
    }
}

/// A slot's defaults: the enum, and its [`Defaults`] impl from the names given.
macro_rules! defaults {
    (
        $(#[$doc:meta])*
        $name:ident: $slot:literal, onnx $onnx:literal,
        { $($(#[$vdoc:meta])* $variant:ident = $text:literal,)+ }
    ) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        pub enum $name {
            $($(#[$vdoc])* $variant,)+
        }

        impl Defaults for $name {
            const SLOT: &'static str = $slot;
            const ALL: &'static [Self] = &[$($name::$variant,)+];
            const ONNX: bool = $onnx;
            fn name(self) -> &'static str {
                match self {
                    $($name::$variant => $text,)+
                }
            }
        }
    };
}

defaults! {
    /// The inpainting slot's default.
    InpaintDefault: "inpainter", onnx true,
    {
        /// Telea's fast marching inpainting, radius 3.
        Telea = "telea",
    }
}

defaults! {
    /// The depth slot's default.
    DepthDefault: "depth estimator", onnx true,
    {
        /// The known depths, holes filled from their borders.
        DepthFill = "depth-fill",
    }
}

defaults! {
    /// The video-depth slot's default.
    VideoDepthDefault: "video depth estimator", onnx true,
    {
        /// [`DepthDefault::DepthFill`] on every frame.
        DepthFill = "depth-fill",
    }
}

defaults! {
    /// The video slot's default (the slot takes no ONNX model).
    VideoDefault: "video generator", onnx false,
    {
        /// Depth-aware morph between the two end frames.
        Morph = "morph",
    }
}

defaults! {
    /// The artifact-removal slot's defaults.
    FixerDefault: "artifact fixer", onnx true,
    {
        /// The render as is.
        Identity = "identity",
        /// An edge-preserving bilateral filter.
        Bilateral = "bilateral",
    }
}

/// The inpainting slot's model.
pub type InpaintModel = Model<InpaintDefault>;
/// The depth slot's model.
pub type DepthModel = Model<DepthDefault>;
/// The video-depth slot's model.
pub type VideoDepthModel = Model<VideoDepthDefault>;
/// The video slot's model.
pub type VideoModel = Model<VideoDefault>;
/// The artifact-removal slot's model.
pub type FixerModel = Model<FixerDefault>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_ones_list_the_known() {
        for text in ["telea", "onnx:cards/lama.json"] {
            assert_eq!(text.parse::<InpaintModel>().unwrap().to_string(), text);
        }
        for text in ["identity", "bilateral", "onnx:fix.json"] {
            assert_eq!(text.parse::<FixerModel>().unwrap().to_string(), text);
        }
        assert_eq!(
            "depth-fill".parse::<DepthModel>().unwrap(),
            Model::Classical(DepthDefault::DepthFill)
        );
        let e = "lama".parse::<InpaintModel>().unwrap_err();
        assert_eq!(
            e.message,
            "unknown inpainter 'lama' (known: telea, or onnx:CARD.json)"
        );
        // The video slot takes no ONNX model: the prefix is not special there.
        let e = "onnx:v.json".parse::<VideoModel>().unwrap_err();
        assert_eq!(
            e.message,
            "unknown video generator 'onnx:v.json' (known: morph)"
        );
    }
}
