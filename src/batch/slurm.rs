//! A Slurm submission folder: one `sbatch` job array per wave, each wave submitted after
//! the one before succeeded, an optional merge after all of them (SPEC.md §21.4).

use super::cost::Request;
use crate::error::{Error, Result};
use crate::io::write_text;
use std::path::Path;

/// Options of a Slurm submission folder.
#[derive(Clone, Debug, Default)]
pub struct SlurmOptions {
    pub partition: Option<String>,
    pub account: Option<String>,
    /// More `#SBATCH` options, one per entry (e.g. `--qos=long`).
    pub extra: Vec<String>,
    /// At most this many tasks of one array at once (`--array=…%N`).
    pub throttle: Option<u32>,
    /// CPUs per task (the worker's thread count); 2 when unset.
    pub cpus: Option<u32>,
}

/// A word for `sh`: single-quoted unless it is plain.
pub fn shell_quote(s: &str) -> String {
    let plain = !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-_./=:,+@%".contains(&b));
    if plain {
        s.into()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// One job array of a submission folder: `tasks` tasks, each running `body` (a shell
/// script's lines after the `#SBATCH` header; `$SLURM_ARRAY_TASK_ID` is the task).
#[derive(Clone, Debug)]
pub struct ArrayWave {
    pub name: String,
    pub tasks: usize,
    pub request: Request,
    pub body: String,
}

/// Write the Slurm submission folder `out`: per wave `wave-N-<name>.sbatch` (a job array,
/// `--output=logs/<name>-%a.out`, relative to `out`, from where `submit.sh` submits), the optional `merge.sbatch`, and `submit.sh`, which
/// submits each wave after the one before succeeded (`afterok`), the merge after every wave
/// ended (`afterany`: it names what failed), prints the ids and writes `job-ids.txt`.
pub fn write_submission(
    out: &Path,
    waves: &[ArrayWave],
    merge: Option<&ArrayWave>,
    opts: &SlurmOptions,
) -> Result<()> {
    let logs = out.join("logs");
    crate::io::create_dir_all(&logs)?;
    let script = |w: &ArrayWave, array: bool| {
        let r = &w.request;
        let mut s = format!(
            "#!/bin/bash\n#SBATCH --job-name=unseen-{}\n#SBATCH --cpus-per-task={}\n\
             #SBATCH --mem={}M\n#SBATCH --time={}\n#SBATCH --output={}\n\
             #SBATCH --open-mode=append\n#SBATCH --kill-on-invalid-dep=yes\n",
            w.name,
            r.cpus,
            r.memory_mb,
            slurm_time(r.time_minutes),
            // Relative to the submission folder (submit.sh submits from there): a path with
            // a space or a quote cannot be an `#SBATCH` value.
            if array {
                format!("logs/{}-%a.out", w.name)
            } else {
                format!("logs/{}.out", w.name)
            }
        );
        if array {
            let throttle = opts.throttle.map_or(String::new(), |t| format!("%{t}"));
            s += &format!("#SBATCH --array=0-{}{throttle}\n", w.tasks.max(1) - 1);
        }
        if let Some(p) = &opts.partition {
            s += &format!("#SBATCH --partition={p}\n");
        }
        if let Some(a) = &opts.account {
            s += &format!("#SBATCH --account={a}\n");
        }
        for e in &opts.extra {
            s += &format!("#SBATCH {e}\n");
        }
        s + "set -eu\n" + &w.body
    };
    let mut submit = String::from(
        "#!/bin/sh\n# Submit the waves to Slurm; prints the job ids.\nset -eu\n\
         cd \"$(dirname \"$0\")\"\n\
         # sbatch --parsable prints <id> or <id>;<cluster>; a refused job stops the script.\n\
         id() { r=$(sbatch --parsable \"$@\") || exit 1; [ -n \"$r\" ] || exit 1; echo \"${r%%;*}\"; }\n",
    );
    let mut ids: Vec<String> = Vec::new();
    for (i, w) in waves.iter().enumerate() {
        let stem = format!("wave-{}-{}", i + 1, w.name);
        write_text(&out.join(format!("{stem}.sbatch")), &script(w, true))?;
        let var = format!("w{}", i + 1);
        let dep = ids
            .last()
            .map_or(String::new(), |p| format!(" --dependency=afterok:${p}"));
        submit += &format!(
            "{var}=$(id{dep} {stem}.sbatch)\necho \"{}: ${var} ({} tasks)\"\n",
            w.name, w.tasks
        );
        ids.push(var);
    }
    let mut all: Vec<String> = ids.iter().map(|v| format!("${v}")).collect();
    if let Some(m) = merge {
        write_text(&out.join("merge.sbatch"), &script(m, false))?;
        // With no wave left to run (every job pooled), the merge alone, at once.
        let dep = if all.is_empty() {
            String::new()
        } else {
            format!(" --dependency=afterany:{}", all.join(":"))
        };
        submit += &format!("merge=$(id{dep} merge.sbatch)\necho \"merge: $merge\"\n");
        all.push("$merge".into());
    }
    submit += &format!("echo {} > job-ids.txt\n", all.join(" "));
    let path = out.join("submit.sh");
    write_text(&path, &submit)?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))
            .map_err(|e| Error::io(&path, e))?;
    }
    Ok(())
}

/// `--time` as Slurm reads it: `D-HH:MM:00`.
fn slurm_time(minutes: u64) -> String {
    format!(
        "{}-{:02}:{:02}:00",
        minutes / 1440,
        minutes % 1440 / 60,
        minutes % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::cost::{Cost, request};

    #[test]
    fn requests_have_their_safety_factors_and_floors() {
        let c = |s: f64, b: f64| Cost {
            seconds: s,
            peak_rss_bytes: b,
            measured: false,
        };
        let r = request(&[c(3600.0, 3e9), c(10.0, 1e6)], 4);
        assert_eq!((r.cpus, r.memory_mb, r.time_minutes), (4, 6000, 180));
        let r = request(&[c(1.0, 1e6)], 2);
        assert_eq!((r.memory_mb, r.time_minutes), (1000, 10));
        assert_eq!(slurm_time(180), "0-03:00:00");
        assert_eq!(slurm_time(1441), "1-00:01:00");
        assert_eq!(shell_quote("a b'c"), r"'a b'\''c'");
        assert_eq!(shell_quote("/x/y-z.json"), "/x/y-z.json");
    }
}
