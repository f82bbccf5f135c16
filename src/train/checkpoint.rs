//! Training checkpoints (SPEC.md §14.8): everything a [`Trainer`] carries from one
//! iteration to the next, so that a run killed at any point and resumed from its last
//! checkpoint reaches the same bits as a run that was never interrupted.
//!
//! The state is: the parameters; Adam's two moments and each group's step count and
//! bias-correction products; the densification statistics; the iteration and active SH
//! degree; the generator's state and INRIA's view stack; the two progress averages. What
//! is not saved is recomputed from the inputs: the scene extent (from the dataset), the
//! per-view loss weights (from `--init`), the reused gradient buffers (every entry is
//! written by each backward).
//!
//! File layout, little-endian:
//!
//! ```text
//! "UNSEENCK"        8 bytes
//! version           u32 (1)
//! header length H   u64
//! header            H bytes of JSON (CheckpointHeader)
//! arrays            for params, Adam m, Adam v: the six arrays in `Param::ALL` order
//!                   (means, sh_dc, sh_rest, opacity_logits, log_scales, quats; f32);
//!                   then grad_accum (f32), count (u32), max_radius (f32)
//! sha256            32 bytes, of everything before
//! ```
//!
//! A reader checks the magic, version, that the array bytes the header announces are
//! exactly the bytes present (before allocating anything for them) and the digest, and
//! names the file in every error.

use crate::error::{Error, Result};
use crate::gaussian::{Gaussians, Param};
use crate::math::sh::num_coeffs;
use crate::rng::Uniform;
use crate::train::adam::GroupStep;
use crate::train::densify::DensifyStats;
use crate::train::trainer::{TrainConfig, Trainer};
use sha2::{Digest, Sha256};
use std::io::Write;
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"UNSEENCK";
const VERSION: u32 = 1;
/// Bytes before the header: magic, version, header length.
const PREFIX: usize = 8 + 4 + 8;
const DIGEST: usize = 32;
/// A header larger than this is not one of ours (it holds a config and a few lists).
const MAX_HEADER: u64 = 64 << 20;

/// `RUN/checkpoint.bin`.
pub fn checkpoint_path(run: &Path) -> PathBuf {
    run.join("checkpoint.bin")
}

/// What a checkpoint says besides the arrays. f64 values are stored as their bits, so the
/// resumed run continues from exactly the same numbers.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CheckpointHeader {
    /// `version::NUMERICS_REVISION` of the writer: a checkpoint from another revision would
    /// not continue to the bits this build computes, so it is refused.
    pub numerics_revision: u32,
    pub config: TrainConfig,
    /// The views trained on, in the dataset's order (a resume must see the same ones).
    pub train_views: Vec<String>,
    /// sha256 of what the run trains on (`train::run`: cameras, training images, depths
    /// and loss weights, the initial scene of a fine-tune): a resume must see the same.
    pub inputs_sha256: String,
    pub iteration: u32,
    pub active_sh_degree: u32,
    pub gaussians: usize,
    pub sh_degree: u32,
    /// The generator's 128-bit state, as 32 hex digits.
    pub rng_state: String,
    pub stack: Vec<usize>,
    pub loss_ema_bits: u64,
    pub psnr_ema_bits: u64,
    /// Per [`crate::gaussian::Param::ALL`] entry: `(t, β1ᵗ bits, β2ᵗ bits)`.
    pub adam_steps: Vec<(u64, u64, u64)>,
    /// The run's bookkeeping so far (`train::run`): not part of the training state, but
    /// the resumed run's summary and manifest continue it.
    pub run: serde_json::Value,
}

/// A checkpoint in memory: header and arrays.
pub struct Checkpoint {
    pub header: CheckpointHeader,
    pub gaussians: Gaussians,
    pub adam_m: Gaussians,
    pub adam_v: Gaussians,
    pub stats: DensifyStats,
}

impl Checkpoint {
    /// Write `t`'s state to `path` (atomically, from the trainer's own arrays: nothing is
    /// copied).
    pub fn save(
        t: &Trainer<'_>,
        inputs_sha256: String,
        run: serde_json::Value,
        path: &Path,
    ) -> Result<()> {
        let d = &t.dataset;
        let header = CheckpointHeader {
            numerics_revision: crate::version::NUMERICS_REVISION,
            config: t.config.clone(),
            train_views: d
                .train
                .iter()
                .map(|&i| d.views[i].camera.name.clone())
                .collect(),
            inputs_sha256,
            iteration: t.iteration,
            active_sh_degree: t.active_sh_degree,
            gaussians: t.gaussians.len(),
            sh_degree: t.gaussians.sh_degree,
            rng_state: format!("{:032x}", t.rng.state()),
            stack: t.stack.clone(),
            loss_ema_bits: t.loss_ema.to_bits(),
            psnr_ema_bits: t.psnr_ema.to_bits(),
            adam_steps: t
                .adam
                .steps
                .iter()
                .map(|s| (s.t, s.beta1_pow.to_bits(), s.beta2_pow.to_bits()))
                .collect(),
            run,
        };
        write_parts(
            path,
            &header,
            [&t.gaussians, &t.adam.m, &t.adam.v],
            &t.stats,
        )
    }

    /// Put the state into `t`, a trainer built on the same dataset and config (its
    /// parameters, optimizer and statistics are replaced).
    pub fn restore(self, t: &mut Trainer<'_>) -> Result<()> {
        let h = self.header;
        let names: Vec<&str> = t
            .dataset
            .train
            .iter()
            .map(|&i| t.dataset.views[i].camera.name.as_str())
            .collect();
        if names != h.train_views {
            return Err(Error::invalid(
                "the checkpoint was trained on other views than this dataset's training views",
            ));
        }
        if h.config != t.config {
            return Err(Error::invalid(
                "the checkpoint was made with another training config",
            ));
        }
        if h.stack.iter().any(|v| !t.dataset.train.contains(v))
            || h.adam_steps.len() != t.adam.steps.len()
            || h.iteration >= h.config.iterations
        {
            return Err(Error::invalid(
                "the checkpoint's view stack, Adam groups or iteration do not fit its run",
            ));
        }
        if self.gaussians.sh_degree != t.config.sh_degree || h.active_sh_degree > t.config.sh_degree
        {
            return Err(Error::invalid(
                "the checkpoint's SH degrees do not fit its training config",
            ));
        }
        let state = u128::from_str_radix(&h.rng_state, 16)
            .map_err(|_| Error::invalid("the checkpoint's generator state is not hex"))?;
        t.gaussians = self.gaussians;
        t.adam.m = self.adam_m;
        t.adam.v = self.adam_v;
        for (s, &(n, b1, b2)) in t.adam.steps.iter_mut().zip(&h.adam_steps) {
            *s = GroupStep {
                t: n,
                beta1_pow: f64::from_bits(b1),
                beta2_pow: f64::from_bits(b2),
            };
        }
        t.stats = self.stats;
        t.iteration = h.iteration;
        t.active_sh_degree = h.active_sh_degree;
        t.rng = Uniform::from_state(state);
        t.stack = h.stack;
        t.loss_ema = f64::from_bits(h.loss_ema_bits);
        t.psnr_ema = f64::from_bits(h.psnr_ema_bits);
        Ok(())
    }

    /// Write to `path` atomically (§10): a kill during the write leaves the previous
    /// checkpoint in place.
    pub fn write(&self, path: &Path) -> Result<()> {
        write_parts(
            path,
            &self.header,
            [&self.gaussians, &self.adam_m, &self.adam_v],
            &self.stats,
        )
    }

    /// Read and check a checkpoint file.
    pub fn read(path: &Path) -> Result<Checkpoint> {
        let bad = |what: String| Error::parse(path, what);
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        if bytes.len() < PREFIX + DIGEST || &bytes[..8] != MAGIC {
            return Err(bad("not an unseen training checkpoint".into()));
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if version != VERSION {
            return Err(bad(format!(
                "checkpoint format version {version}, this build reads {VERSION}"
            )));
        }
        let (body, digest) = bytes.split_at(bytes.len() - DIGEST);
        if Sha256::digest(body).as_slice() != digest {
            return Err(bad(
                "the checksum does not match (truncated or damaged file)".into(),
            ));
        }
        let hlen = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes"));
        if hlen > MAX_HEADER || hlen as usize > body.len() - PREFIX {
            return Err(bad(format!("header length {hlen} does not fit the file")));
        }
        let hend = PREFIX + hlen as usize;
        let header: CheckpointHeader = serde_json::from_slice(&body[PREFIX..hend])
            .map_err(|e| bad(format!("invalid header: {e}")))?;
        if header.numerics_revision != crate::version::NUMERICS_REVISION {
            return Err(bad(format!(
                "written at numerics revision {}, this build is revision {}: it would not \
                 resume to the same bits",
                header.numerics_revision,
                crate::version::NUMERICS_REVISION
            )));
        }
        if header.sh_degree > crate::math::sh::MAX_SH_DEGREE {
            return Err(bad(format!("SH degree {} > 5", header.sh_degree)));
        }
        // Floats per Gaussian in one parameter set, then three sets and the statistics.
        let n = header.gaussians as u128;
        let per = 3 + 3 + 4 + 1 + 3 + (num_coeffs(header.sh_degree) as u128 - 1) * 3;
        let want = n * (3 * per + 3) * 4;
        let have = (body.len() - hend) as u128;
        if want != have {
            return Err(bad(format!(
                "the header announces {} Gaussians ({want} array bytes) but the file holds \
                 {have} array bytes",
                header.gaussians
            )));
        }
        let mut r = &body[hend..];
        let mut sets = Vec::with_capacity(3);
        for _ in 0..3 {
            let mut g = Gaussians::zeros(header.gaussians, header.sh_degree)?;
            for p in Param::ALL {
                let a = g.param_mut(p);
                let n = a.len();
                a.copy_from_slice(&read_f32s(&mut r, n));
            }
            sets.push(g);
        }
        let n = header.gaussians;
        let stats = DensifyStats {
            grad_accum: read_f32s(&mut r, n),
            count: read_u32s(&mut r, n),
            max_radius: read_f32s(&mut r, n),
        };
        debug_assert!(r.is_empty());
        let adam_v = sets.pop().expect("three sets");
        let adam_m = sets.pop().expect("three sets");
        let gaussians = sets.pop().expect("three sets");
        if gaussians.means.iter().flatten().any(|x| !x.is_finite()) {
            return Err(bad("non-finite Gaussian means".into()));
        }
        Ok(Checkpoint {
            header,
            gaussians,
            adam_m,
            adam_v,
            stats,
        })
    }
}

/// The file layout (module docs) from its parts.
fn write_parts(
    path: &Path,
    header: &CheckpointHeader,
    sets: [&Gaussians; 3],
    stats: &DensifyStats,
) -> Result<()> {
    let header = serde_json::to_vec(header).expect("header serializes");
    crate::io::write_atomic(path, |w| {
        let mut w = HashingWriter {
            inner: w,
            hash: Sha256::new(),
        };
        w.write_all(MAGIC)?;
        w.write_all(&VERSION.to_le_bytes())?;
        w.write_all(&(header.len() as u64).to_le_bytes())?;
        w.write_all(&header)?;
        for g in sets {
            for p in Param::ALL {
                write_f32s(&mut w, g.param(p))?;
            }
        }
        write_f32s(&mut w, &stats.grad_accum)?;
        for c in &stats.count {
            w.write_all(&c.to_le_bytes())?;
        }
        write_f32s(&mut w, &stats.max_radius)?;
        let digest = w.hash.finalize();
        w.inner.write_all(&digest)
    })
}

fn write_f32s(w: &mut impl Write, v: &[f32]) -> std::io::Result<()> {
    // In blocks, so a 100 MB array is not copied whole.
    let mut buf = [0u8; 4096];
    for chunk in v.chunks(buf.len() / 4) {
        for (b, x) in buf.chunks_exact_mut(4).zip(chunk) {
            b.copy_from_slice(&x.to_le_bytes());
        }
        w.write_all(&buf[..chunk.len() * 4])?;
    }
    Ok(())
}

/// The next `n` 32-bit words of `r` (the caller checked the length).
fn read_u32s(r: &mut &[u8], n: usize) -> Vec<u32> {
    let (head, rest) = r.split_at(n * 4);
    *r = rest;
    head.chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect()
}

fn read_f32s(r: &mut &[u8], n: usize) -> Vec<f32> {
    read_u32s(r, n).into_iter().map(f32::from_bits).collect()
}

/// A writer that hashes what passes through.
struct HashingWriter<W: Write> {
    inner: W,
    hash: Sha256,
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hash.update(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}
