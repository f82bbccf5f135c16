//! File output that never leaves a half-written file under its final name, and image I/O.
//!
//! Every writer goes through [`write_atomic`]: the data is written to a temporary file in
//! the destination folder, synced, then renamed over the destination.

pub mod image;
pub mod json_float;
pub mod manifest;
pub mod npy;

use crate::error::{Error, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Write a file atomically: `write` fills a temporary sibling, which is then renamed to
/// `path`. On any error the temporary file is removed and `path` is untouched.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<()> {
    let (tmp, file) = Temporary::create_file(temp_sibling(path)).map_err(|e| Error::io(path, e))?;
    let result = (|| -> std::io::Result<()> {
        let mut w = BufWriter::new(file);
        write(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        tmp.rename_to(path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(tmp.path());
        Error::io(path, e)
    })
}

/// Every temporary file or folder this process is writing (§10), so that an interrupt can
/// remove them before the process exits ([`abandon_temporaries`]).
static IN_FLIGHT: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

fn in_flight() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    // A panic while holding the lock leaves the list itself consistent.
    IN_FLIGHT.lock().unwrap_or_else(|e| e.into_inner())
}

/// A temporary file or folder in flight: created and registered under the registry's lock
/// (an interrupt's sweep either sees it or runs before it exists and then holds the lock
/// until the process exits), renamed into place under the lock (an interrupt sees either
/// the temporary or the finished output, never a rename half done), unregistered when
/// dropped. Removing the temporary after a failure stays the owner's job.
pub(crate) struct Temporary(PathBuf);

impl Temporary {
    /// Create the file `path` (truncating) and register it.
    pub(crate) fn create_file(path: PathBuf) -> std::io::Result<(Temporary, File)> {
        let mut list = in_flight();
        let f = File::create(&path)?;
        list.push(path.clone());
        Ok((Temporary(path), f))
    }

    /// Create the folder `path` (its parent must exist) and register it.
    pub(crate) fn create_dir(path: PathBuf) -> std::io::Result<Temporary> {
        let mut list = in_flight();
        std::fs::create_dir(&path)?;
        list.push(path.clone());
        Ok(Temporary(path))
    }

    /// Register a path that does not exist yet and that only a rename will create.
    pub(crate) fn register(path: PathBuf) -> Temporary {
        in_flight().push(path.clone());
        Temporary(path)
    }

    pub(crate) fn path(&self) -> &Path {
        &self.0
    }

    /// `rename(temporary, to)` under the registry's lock.
    pub(crate) fn rename_to(&self, to: &Path) -> std::io::Result<()> {
        let _held = in_flight();
        std::fs::rename(&self.0, to)
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        let mut list = in_flight();
        if let Some(i) = list.iter().position(|p| *p == self.0) {
            list.swap_remove(i);
        }
    }
}

/// For an interrupt handler that exits right after: remove every temporary in flight and
/// keep the registry locked, so no temporary is created or renamed into place afterwards.
/// Returns how many were removed. Finished outputs are left as they are. **The process
/// must exit next**: every later atomic write in any thread blocks forever.
pub fn abandon_temporaries() -> usize {
    let list = in_flight();
    let mut n = 0;
    for p in list.iter() {
        let gone = if p.is_dir() {
            std::fs::remove_dir_all(p)
        } else {
            std::fs::remove_file(p)
        };
        n += usize::from(gone.is_ok());
    }
    // Held until the process exits.
    std::mem::forget(list);
    n
}

/// `dir/.name.tmp-<host>-<pid>-<random>`: same folder (so rename is atomic), hidden, and
/// unique across processes and hosts sharing the folder ([`unique_suffix`]).
pub(crate) fn temp_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", unique_suffix()))
}

/// This machine's host name as it appears in temporaries' names: letters, digits, `.` and
/// `_` only (anything else becomes `_`), so that `-` separates the name's fields; `host`
/// when the name cannot be read.
pub fn host_name() -> String {
    static NAME: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    NAME.get_or_init(|| {
        let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .or_else(|_| std::fs::read_to_string("/etc/hostname"))
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .or_else(|| std::env::var("COMPUTERNAME").ok())
            .unwrap_or_default();
        let name: String = raw
            .trim()
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '.' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if name.is_empty() { "host".into() } else { name }
    })
    .clone()
}

/// This process's PID namespace (Linux: the inode of `/proc/self/ns/pid`; 0 where it
/// cannot be read): two containers on one host have the same host name but not the same
/// namespace, and their process ids mean different processes.
pub fn pid_namespace() -> u64 {
    static NS: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *NS.get_or_init(|| {
        std::fs::read_link("/proc/self/ns/pid")
            .ok()
            .and_then(|l| {
                let l = l.to_string_lossy().into_owned();
                l.strip_prefix("pid:[")?.strip_suffix(']')?.parse().ok()
            })
            .unwrap_or(0)
    })
}

/// `<host>-<pid namespace>-<pid>-<16 hex digits>`: a name no other writer uses, on this
/// machine or on another one sharing the folder (SPEC.md §10). The last field is random
/// (the standard library's per-process random hash keys, mixed with the clock and a
/// counter), so two hosts whose processes have the same id still differ.
pub fn unique_suffix() -> String {
    use std::hash::{BuildHasher, Hasher};
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos()),
    );
    h.write_u64(COUNTER.fetch_add(1, Ordering::Relaxed));
    format!(
        "{}-{}-{}-{:016x}",
        host_name(),
        pid_namespace(),
        std::process::id(),
        h.finish()
    )
}

/// The writer of a temporary named by [`unique_suffix`] (`….tmp-<host>-<ns>-<pid>-<hex>`
/// or `….stale-…`): its host, PID namespace and process id; `None` for any other name.
pub fn temporary_owner(name: &str) -> Option<(String, u64, u32)> {
    let tail = name
        .rsplit_once(".tmp-")
        .or_else(|| name.rsplit_once(".stale-"))?
        .1;
    let mut fields = tail.rsplitn(4, '-');
    let random = fields.next()?;
    let pid = fields.next()?.parse().ok()?;
    let ns = fields.next()?.parse().ok()?;
    let host = fields.next()?;
    (random.len() == 16 && random.bytes().all(|b| b.is_ascii_hexdigit()) && !host.is_empty())
        .then(|| (host.to_string(), ns, pid))
}

/// Whether the temporary `name` was left by a process of this host and PID namespace that
/// no longer runs (Linux: no `/proc/<pid>`): such a temporary is abandoned whatever its
/// age. Another host's or namespace's, or one where processes cannot be looked up, is
/// never taken for abandoned here (its age decides). The look-up needs a `/proc` that
/// shows the writer: the same user's processes, or no `hidepid` mount option.
pub fn temporary_is_orphan(name: &str) -> bool {
    let Some((host, ns, pid)) = temporary_owner(name) else {
        return false;
    };
    host == host_name()
        && ns == pid_namespace()
        && ns != 0
        && pid != std::process::id()
        && Path::new("/proc/self").exists()
        && !Path::new(&format!("/proc/{pid}")).exists()
}

/// Remove the `.<name>.tmp-…` files a killed writer left (§10) directly in `dir`: those of
/// a process of this host that no longer runs ([`temporary_is_orphan`]) and those older
/// than [`ABANDONED_AFTER`]. A live writer's — another `--only` worker of the same run, on
/// this host or another — is left alone, and a file that vanishes meanwhile is fine.
pub fn remove_stale_temporaries(dir: &Path) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p.is_file() && name.starts_with('.') && name.contains(".tmp-") && abandoned(&e, &name) {
            match std::fs::remove_file(&p) {
                Err(err) if err.kind() != std::io::ErrorKind::NotFound => {
                    return Err(Error::io(&p, err));
                }
                _ => {}
            }
        }
    }
    Ok(())
}

/// How old a temporary must be to count as abandoned whoever wrote it: a writer renames a
/// file or publishes a cache entry within seconds, so a day-old one belongs to a process
/// that was killed (host clocks may differ by minutes, not by a day).
pub const ABANDONED_AFTER: std::time::Duration = std::time::Duration::from_secs(24 * 3600);

/// Whether the temporary `e` (named `name`) is abandoned: an orphan of this host, or older
/// than [`ABANDONED_AFTER`].
pub fn abandoned(e: &std::fs::DirEntry, name: &str) -> bool {
    temporary_is_orphan(name)
        || e.metadata()
            .and_then(|m| m.modified())
            .is_ok_and(|t| t.elapsed().is_ok_and(|a| a >= ABANDONED_AFTER))
}

/// Create a directory and its parents, naming it in the error.
pub fn create_dir_all(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))
}

/// Write a text file atomically.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    write_atomic(path, |w| w.write_all(text.as_bytes()))
}

/// Lower-case hex SHA-256 of `bytes` (manifests).
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    hex(&Sha256::digest(bytes))
}

/// Lower-case hex of a digest.
pub fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// Peak resident memory of this process in bytes (Linux `VmHWM`), if the OS tells.
pub fn peak_memory_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Reset the peak resident memory mark (Linux: `5` into `/proc/self/clear_refs`), so the
/// next [`peak_memory_bytes`] measures from now; false where the OS does not allow it.
pub fn reset_peak_memory() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// Wall time and peak resident memory of one stage of work (a training run's loading or
/// iterations, a pipeline step). The peak is the process's high-water mark since the stage
/// began (Linux: reset through `/proc/self/clear_refs`); stages that run side by side
/// share it. `None` where the OS does not tell.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Cost {
    pub seconds: f64,
    pub peak_rss_bytes: Option<u64>,
}

/// Measures a [`Cost`] from its creation.
pub struct CostMeter {
    start: std::time::Instant,
    peak_reset: bool,
}

impl CostMeter {
    /// Start measuring: freed memory the process kept is returned to the OS first
    /// ([`crate::sys::release_freed_memory`]), so the peak is the stage's own.
    pub fn start() -> CostMeter {
        crate::sys::release_freed_memory();
        let peak_reset = reset_peak_memory();
        CostMeter {
            start: std::time::Instant::now(),
            peak_reset,
        }
    }
    pub fn finish(&self) -> Cost {
        Cost {
            seconds: self.start.elapsed().as_secs_f64(),
            peak_rss_bytes: peak_memory_bytes().filter(|_| self.peak_reset),
        }
    }
}

/// A file-name-safe version of a camera name.
pub fn file_stem(name: &str) -> String {
    let stem = Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned());
    stem.unwrap_or_else(|| name.to_string())
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}
