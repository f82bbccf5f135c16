//! The run directory of `unseen extrapolate` (SPEC.md §20.8): one folder per step, each
//! closed by a `manifest.json` written last, so a step is done exactly when its manifest
//! exists, its `inputs_sha256` equals what the step would be computed from now, and every
//! listed file still has its sha256. `--resume` skips such steps and recomputes the others
//! from scratch (their folder is removed first); a run killed at any moment therefore
//! resumes to the same bits as an uninterrupted run.
//!
//! A step's inputs are its own settings and the manifests' digests of the steps it reads,
//! so a change anywhere upstream invalidates everything downstream, and two variants of a
//! run that share a step's inputs share its digest (content addressing).
//!
//! With a *step cache* (a folder shared by many run directories, e.g. the variants of an
//! audit), every finished step is also published there under the hash of its name and
//! inputs, and a step whose verified twin is in the cache is copied (hard-linked where the
//! file system allows) instead of computed: the same files, the same manifest, the same
//! digest, so everything downstream is keyed exactly as if it had been computed here.

use super::Event;
use super::steps::Step;
use crate::error::{Error, Result};
use crate::io::manifest::{FileEntry, Manifest, inputs_sha256};
use crate::io::{
    Temporary, create_dir_all, remove_stale_temporaries, sha256_hex, unique_suffix, write_text,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// An open run directory.
pub struct RunDir {
    pub root: PathBuf,
    resume: bool,
    /// A scoped run (`--only`, `--until`, a wave): steps done here are verified and
    /// reused even without `resume`.
    scoped: bool,
    /// Digest of everything the run reads (scene, dataset views, candidates, crate and
    /// conventions version): part of every step's inputs, so no step is reused across
    /// different data.
    base: String,
    /// Shared step cache ([`RunDir::with_cache`]).
    cache: Option<PathBuf>,
    /// The output folder as opened: checked before every step and every file.
    guard: RootGuard,
}

/// The output folder as the run opened it, held open: a folder removed or replaced during
/// the run (a cleanup script, another job) is an error at the next step or file, never
/// silently re-created with the earlier steps missing. Holding the folder open keeps its
/// inode from being reused, so "the same folder" is exact: the path's (device, inode) is the
/// open folder's and the open folder still has a link.
#[derive(Clone, Debug)]
struct RootGuard {
    root: PathBuf,
    #[cfg(unix)]
    open: std::sync::Arc<std::fs::File>,
}

impl RootGuard {
    fn new(root: &Path) -> Result<RootGuard> {
        Ok(RootGuard {
            root: root.to_path_buf(),
            #[cfg(unix)]
            open: std::sync::Arc::new(std::fs::File::open(root).map_err(|e| Error::io(root, e))?),
        })
    }

    #[cfg(unix)]
    fn check(&self) -> Result<()> {
        use std::os::unix::fs::MetadataExt;
        let gone = |why: String| {
            Err(Error::invalid(format!(
                "the output folder disappeared during the run ({why}); nothing was re-created"
            ))
            .at(&self.root))
        };
        let held = self.open.metadata().map_err(|e| Error::io(&self.root, e))?;
        if held.nlink() == 0 {
            return gone("removed".into());
        }
        match std::fs::metadata(&self.root) {
            Ok(m) if (m.dev(), m.ino()) == (held.dev(), held.ino()) => Ok(()),
            Ok(_) => Err(Error::invalid(
                "the output folder was replaced by another during the run",
            )
            .at(&self.root)),
            Err(e) => gone(e.to_string()),
        }
    }

    #[cfg(not(unix))]
    fn check(&self) -> Result<()> {
        std::fs::metadata(&self.root)
            .map(|_| ())
            .map_err(|e| Error::io(&self.root, e))
    }
}

/// How a run treats one step of its selection ([`super::steps::Selection`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Computed, unless a verified result with the same inputs is here or in the cache.
    Compute,
    /// Read by a step of the scope and not part of it: it must be done (here, or in the
    /// cache); a folder here that does not verify is another worker's and is left alone.
    Verify,
}

/// What a finished (or verified) step hands downstream.
#[derive(Clone, Debug)]
pub struct StepDone {
    pub name: String,
    pub dir: PathBuf,
    /// sha256 of the step's manifest bytes: the key of everything it wrote.
    pub digest: String,
    pub skipped: bool,
}

impl RunDir {
    /// Open `root` for a new run (it must not exist or be empty) or, with `resume`, for
    /// continuing one.
    pub fn open(root: &Path, resume: bool, scoped: bool, base: &str) -> Result<RunDir> {
        if scoped && !resume && root.is_dir() {
            return Err(Error::invalid(
                "--only, --until and --wave continue a run directory: pass --resume",
            )
            .at(root));
        }
        if root.is_file() {
            return Err(Error::invalid("the output path is a file").at(root));
        }
        if !resume && root.is_dir() {
            let mut entries = std::fs::read_dir(root).map_err(|e| Error::io(root, e))?;
            if entries.next().is_some() {
                return Err(Error::invalid(
                    "the output folder exists and is not empty (pass --resume to continue that run)",
                )
                .at(root));
            }
        }
        create_dir_all(root)?;
        if resume {
            // Files outside the steps (config, summaries): a step's own folder is removed
            // whenever the step is recomputed, so its temporaries go with it; other jobs'
            // steps in flight are left alone.
            remove_stale_temporaries(root)?;
            remove_stale_temporaries(&super::steps::Stage::Eval.dir(root))?;
        }
        Ok(RunDir {
            root: root.to_path_buf(),
            resume,
            scoped,
            base: base.to_string(),
            cache: None,
            guard: RootGuard::new(root)?,
        })
    }

    /// Reuse and publish finished steps through the shared folder `cache` (created).
    pub fn with_cache(mut self, cache: &Path) -> Result<RunDir> {
        if cache.is_file() {
            return Err(Error::invalid("the step cache path is a file").at(cache));
        }
        // Temporaries of killed publishers go; those another job may be writing stay.
        create_dir_all(cache)?;
        sweep_abandoned(cache);
        self.cache = Some(cache.to_path_buf());
        Ok(self)
    }

    /// Run `step` (its folder, e.g. `stage1/view_x`) from `inputs` unless a verified result
    /// exists; `compute` writes its files through the [`StepWriter`]. With [`Mode::Verify`]
    /// the step is never computed: not done is an error.
    pub fn step(
        &self,
        step: &Step,
        mode: Mode,
        inputs: serde_json::Value,
        on_event: &(dyn Fn(Event) + Sync),
        compute: impl FnOnce(&mut StepWriter) -> Result<()>,
    ) -> Result<StepDone> {
        self.guard.check()?;
        let name = step.to_string();
        let name = name.as_str();
        let dir = step.dir(&self.root);
        let inputs = serde_json::json!({ "run": self.base, "step": inputs });
        let inputs_sha256 = inputs_sha256(&inputs);
        // A step already done here (`--resume`, scoped runs) or in the cache.
        let reuse = |dir: PathBuf, digest: String, event: Event| {
            on_event(event);
            Ok(StepDone {
                name: name.into(),
                dir,
                digest,
                skipped: true,
            })
        };
        // Why a step folder here is not taken: said once, before the step is recomputed,
        // so that a damaged file is never silently replaced.
        let mut not_taken = None;
        if self.resume || self.scoped {
            match check(&dir, &inputs_sha256) {
                Ok(digest) => return reuse(dir, digest, Event::StepSkipped { step: name.into() }),
                Err(why) => not_taken = why,
            }
        }
        // A step the scope only reads that has a folder here is another worker's (in
        // flight, or left damaged): never replaced from the cache.
        let others = mode == Mode::Verify && dir.exists();
        let cached = self
            .cache_entry(name, &inputs_sha256)
            .filter(|_| !others)
            .and_then(|c| match check(&c, &inputs_sha256) {
                Ok(digest) => Some((c, digest)),
                Err(Some(why)) => {
                    on_event(Event::Note(format!(
                        "{name}: the step cache's entry is not usable ({why})"
                    )));
                    None
                }
                Err(None) => None,
            });
        if let Some((cached, digest)) = cached {
            if dir.exists() {
                std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
            }
            // The copy is checked like any step on disk; a copy that fails or does not
            // verify (the entry replaced meanwhile) is dropped and the step computed.
            if copy_step(&cached, &dir).is_ok()
                && verified(&dir, &inputs_sha256).as_ref() == Some(&digest)
            {
                return reuse(dir, digest, Event::StepCached { step: name.into() });
            }
        }
        if mode == Mode::Verify {
            // Not this worker's step (another worker may be writing it): left alone.
            return Err(Error::invalid(format!(
                "step {name} is not done in this run directory and the requested steps read it (run up to it first with --until {name})"
            ))
            .at(&self.root));
        }
        if let Some(why) = not_taken {
            on_event(Event::Note(format!("{name}: {why}: recomputed")));
        }
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        }
        create_dir_all(&dir)?;
        on_event(Event::StepStarted { step: name.into() });
        let meter = crate::io::CostMeter::start();
        let mut w = StepWriter {
            dir: dir.clone(),
            files: Vec::new(),
            guard: self.guard.clone(),
        };
        // Steps do not nest, so the step's name is never in the message yet.
        compute(&mut w).map_err(|e| Error {
            message: format!("step {name}: {}", e.message),
            ..e
        })?;
        let mut files = w.files;
        files.sort_by(|a, b| a.path.cmp(&b.path));
        let cost = meter.finish();
        let secs = cost.seconds;
        // Outside the manifest (timings differ run to run), written before it: a step is
        // complete only once its manifest exists.
        let text = serde_json::to_string(&cost).expect("serializes") + "\n";
        self.guard.check()?;
        write_text(&dir.join(TIMING_FILE), &text)?;
        let digest = Manifest::new("extrapolate", name, inputs, files).write(&dir)?;
        if let Some(cached) = self.cache_entry(name, &inputs_sha256) {
            // Best effort: a cache that cannot be written costs reuse, not the step.
            if let Err(e) = publish(&dir, &cached, &inputs_sha256) {
                on_event(Event::Note(format!(
                    "step cache not updated: {}",
                    e.message
                )));
            }
        }
        on_event(Event::StepFinished {
            step: name.into(),
            seconds: secs,
        });
        Ok(StepDone {
            name: name.into(),
            dir,
            digest,
            skipped: false,
        })
    }

    /// The cache folder of step `name` with these inputs (`None` without a cache).
    fn cache_entry(&self, name: &str, inputs_sha256: &str) -> Option<PathBuf> {
        let key = sha256_hex(format!("{name}\n{inputs_sha256}").as_bytes());
        self.cache.as_ref().map(|c| c.join(key))
    }

    /// What each of `steps` cost when it was computed (this run or an earlier one).
    pub fn timings(&self, steps: &[StepDone]) -> BTreeMap<String, crate::io::Cost> {
        steps
            .iter()
            .filter_map(|s| {
                let t = std::fs::read(s.dir.join(TIMING_FILE)).ok()?;
                Some((s.name.clone(), serde_json::from_slice(&t).ok()?))
            })
            .collect()
    }
}

/// What a step cost, beside its manifest and not in it (it differs run to run).
pub const TIMING_FILE: &str = "cost.json";

/// Copy the step folder `from` into `to`, `manifest.json` last (a step is done only once its
/// manifest verifies, so a copy cut short is never taken for a step): files hard-linked
/// where possible (step files are only ever replaced by rename, never written in place),
/// else copied.
/// `to` is created with its parents; below it, folders are created one level at a time,
/// so a copy into a temporary that an interrupt removed fails instead of re-creating it.
fn copy_step(from: &Path, to: &Path) -> Result<()> {
    create_dir_all(to)?;
    copy_into(from, to)
}

/// [`copy_step`] into the existing folder `to`.
fn copy_into(from: &Path, to: &Path) -> Result<()> {
    fn walk(from: &Path, to: &Path, top: bool) -> Result<()> {
        if !top {
            std::fs::create_dir(to).map_err(|e| Error::io(to, e))?;
        }
        let mut entries: Vec<_> = std::fs::read_dir(from)
            .map_err(|e| Error::io(from, e))?
            .collect::<std::io::Result<_>>()
            .map_err(|e| Error::io(from, e))?;
        entries.sort_by_key(|e| (top && e.file_name() == "manifest.json", e.file_name()));
        for e in entries {
            let (src, dst) = (e.path(), to.join(e.file_name()));
            if src.is_dir() {
                walk(&src, &dst, false)?;
            } else if std::fs::hard_link(&src, &dst).is_err() {
                std::fs::copy(&src, &dst).map_err(|err| Error::io(&src, err))?;
            }
        }
        Ok(())
    }
    walk(from, to, true)
}

/// Remove the temporaries (`.<key>.tmp-*`, `.<key>.stale-*` folders) that killed
/// publishers left in `cache` ([`crate::io::abandoned`]: at once when their writer was a
/// process of this host that no longer runs, else once they are a day old — a younger one
/// of another host may belong to a job publishing right now). Best effort.
fn sweep_abandoned(cache: &Path) {
    let Ok(entries) = std::fs::read_dir(cache) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let temporary =
            name.starts_with('.') && (name.contains(".tmp-") || name.contains(".stale-"));
        if temporary && crate::io::abandoned(&e, &name) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Publish a finished step into the cache entry `to`: copied into a temporary sibling, then
/// renamed into place, so an entry appears whole. The rename fails when `to` exists (a
/// folder is never renamed onto a non-empty one): a verified entry there is kept (another
/// job published the same step: same bits); one that does not verify is first renamed
/// aside, then removed, and the rename tried again — so no job ever deletes in place an
/// entry another job may be reading, nor replaces a verified one.
fn publish(from: &Path, to: &Path, inputs_sha256: &str) -> Result<()> {
    if verified(to, inputs_sha256).is_some() {
        return Ok(());
    }
    let parent = to.parent().unwrap_or(Path::new("."));
    let key = to.file_name().and_then(|n| n.to_str()).unwrap_or("step");
    let tmp = Temporary::create_dir(parent.join(format!(".{key}.tmp-{}", unique_suffix())))
        .map_err(|e| Error::io(to, e))?;
    let r = copy_into(from, tmp.path()).and_then(|()| {
        if tmp.rename_to(to).is_ok() || verified(to, inputs_sha256).is_some() {
            return Ok(());
        }
        // An unverified entry (damaged, or left by an older layout): aside, then replaced.
        let aside = Temporary::register(parent.join(format!(".{key}.stale-{}", unique_suffix())));
        if std::fs::rename(to, aside.path()).is_ok() {
            let _ = std::fs::remove_dir_all(aside.path());
        }
        match tmp.rename_to(to) {
            // Another job renamed its copy into place first: keep that one.
            Err(_) if verified(to, inputs_sha256).is_some() => Ok(()),
            r => r.map_err(|e| Error::io(to, e)),
        }
    });
    if tmp.path().exists() {
        let _ = std::fs::remove_dir_all(tmp.path());
    }
    r
}

/// The manifest digest when `dir` holds a complete step with these inputs.
fn verified(dir: &Path, inputs_sha256: &str) -> Option<String> {
    check(dir, inputs_sha256).ok()
}

/// Whether the step folder `dir` holds a finished step with these inputs: `Ok(digest)`, or
/// why not — `None` when there is nothing there at all (never started), else the first
/// fault found (interrupted, manifest damaged, other inputs, a file missing or changed).
fn check(dir: &Path, inputs_sha256: &str) -> std::result::Result<String, Option<String>> {
    let bytes = match std::fs::read(dir.join("manifest.json")) {
        Ok(b) => b,
        Err(_) if !dir.exists() => return Err(None),
        Err(_) => {
            return Err(Some(
                "no manifest.json (interrupted before it was written)".into(),
            ));
        }
    };
    let m: Manifest = serde_json::from_slice(&bytes)
        .map_err(|e| Some(format!("manifest.json is damaged ({e})")))?;
    if m.inputs_sha256 != inputs_sha256 {
        return Err(Some("it was computed from other inputs".into()));
    }
    for f in &m.files {
        let b = std::fs::read(dir.join(&f.path))
            .map_err(|e| Some(format!("{} cannot be read ({e})", f.path)))?;
        if sha256_hex(&b) != f.sha256 {
            return Err(Some(format!(
                "{} does not match its sha256 in manifest.json",
                f.path
            )));
        }
    }
    Ok(sha256_hex(&bytes))
}

/// Writes a step's files (atomically) and records their hashes.
pub struct StepWriter {
    dir: PathBuf,
    files: Vec<FileEntry>,
    guard: RootGuard,
}

impl StepWriter {
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Write `rel` with `write(path)` (which must write atomically), then hash it.
    pub fn put(&mut self, rel: &str, write: impl FnOnce(&Path) -> Result<()>) -> Result<PathBuf> {
        if self.files.iter().any(|f| f.path == rel) {
            return Err(Error::invalid(format!(
                "{rel} is written twice in one step"
            )));
        }
        let p = self.dir.join(rel);
        // Its folders are created as needed: only while the output folder is the run's.
        self.guard.check()?;
        if let Some(parent) = p.parent() {
            create_dir_all(parent)?;
        }
        write(&p)?;
        let b = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
        self.files.push(FileEntry::new(rel, &b));
        Ok(p)
    }

    pub fn json<T: serde::Serialize>(&mut self, rel: &str, v: &T) -> Result<PathBuf> {
        let text = serde_json::to_string_pretty(v).expect("serializes") + "\n";
        self.put(rel, |p| write_text(p, &text))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Removes the folder when dropped (also when the test panics).
    struct Scratch(PathBuf);
    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// Old cache temporaries go, young ones (a publisher at work) and entries stay; a young
    /// one of a dead process of this host and namespace goes, a live process's (a child
    /// that is still running) and another host's or namespace's stay.
    #[test]
    fn sweep_removes_only_abandoned_temporaries() {
        let root =
            Scratch(std::env::temp_dir().join(format!("unseen-sweep-{}", std::process::id())));
        let day = std::time::Duration::from_secs(24 * 3600);
        let two_days_ago = std::time::SystemTime::now() - 2 * day;
        let make = |name: &str, old: bool| {
            let p = root.0.join(name);
            std::fs::create_dir_all(p.join("sub")).unwrap();
            if old {
                std::fs::File::open(&p)
                    .unwrap()
                    .set_modified(two_days_ago)
                    .unwrap();
            }
            p
        };
        let old_tmp = make(".key.tmp-1-2-3", true);
        let old_stale = make(".key.stale-1-2-3", true);
        let young_tmp = make(".key.tmp-4-5-6", false);
        let old_entry = make("key", true);
        let (host, ns) = (crate::io::host_name(), crate::io::pid_namespace());
        let dead_pid = u32::try_from(i32::MAX).unwrap(); // above Linux's pid_max
        let mut child = std::process::Command::new("sleep")
            .arg("30")
            .spawn()
            .unwrap();
        let named = |kind: &str, host: &str, ns: u64, pid: u32| {
            make(
                &format!(".key.{kind}-{host}-{ns}-{pid}-0123456789abcdef"),
                false,
            )
        };
        let orphan = named("tmp", &host, ns, dead_pid);
        let live = named("tmp", &host, ns, child.id());
        let elsewhere = named("stale", &format!("{host}x"), ns, dead_pid);
        let other_ns = named("tmp", &host, ns + 1, dead_pid);
        sweep_abandoned(&root.0);
        child.kill().unwrap();
        child.wait().unwrap();
        assert!(!old_tmp.exists() && !old_stale.exists());
        assert!(young_tmp.exists() && old_entry.exists());
        if ns != 0 {
            assert!(!orphan.exists(), "a dead local writer's temporary stays");
        }
        assert!(live.exists() && elsewhere.exists() && other_ns.exists());
    }

    /// Temporaries' names carry their writer; the host field never contains `-`.
    #[test]
    fn temporary_names_are_unique_and_name_their_writer() {
        use crate::io::{host_name, temporary_owner, unique_suffix};
        let (a, b) = (unique_suffix(), unique_suffix());
        assert_ne!(a, b);
        assert!(!host_name().contains('-') && !host_name().is_empty());
        let owner = temporary_owner(&format!(".key.tmp-{a}"));
        let ns = crate::io::pid_namespace();
        assert_eq!(owner, Some((host_name(), ns, std::process::id())));
        assert_eq!(temporary_owner(".key.tmp-1-2-3"), None);
        assert_eq!(temporary_owner("key"), None);
    }
}
