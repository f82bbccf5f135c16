"""Assemble the revision-2 batch of a quick audit (seeds 0-3) as an audit.json of its
revision: seeds 0-2 from the audit committed at revision 2 (git history), seed 3 from the
`audit_job.json` files the revision-2 binary (commit ac4aaab) wrote with `--only`.

usage: python3 assemble.py ROOM COMMIT AUDIT_PATH JOBS_DIR OUT
"""
import json
import pathlib
import subprocess
import sys

room, commit, path, jobs, out = sys.argv[1:]
old = json.loads(subprocess.check_output(["git", "show", f"{commit}:{path}"]))
results = [r for r in old["results"] if r["seed"] in (0, 1, 2)]
seen = {(r["generator"], r["variant"], r["seed"]): r for r in results}
extra = 0
for f in sorted(pathlib.Path(jobs).glob("runs/*/*/seed-*/audit_job.json")):
    j = json.loads(f.read_text())
    k = (j["generator"], j["variant"], j["seed"])
    if k in seen:
        # A job recomputed by the revision-2 binary must reproduce the committed result.
        assert seen[k]["last"] == j["last"] and seen[k]["original"] == j["original"], k
        continue
    assert j["seed"] == 3, k
    results.append(j)
    extra += 1
assert extra == 18, extra
assert len(results) == 4 * 18, len(results)
report = {
    "numerics_revision": 2,
    "crate_version": "0.1.0",
    "dataset": room,
    "preset": old["preset"],
    "train_iterations": old["train_iterations"],
    "train_resolution": old.get("train_resolution", 2),
    "results": sorted(results, key=lambda r: (r["seed"], r["generator"], r["variant"])),
}
pathlib.Path(out).write_text(json.dumps(report, indent=1) + "\n")
print(f"{out}: {len(results)} results, seeds 0-3, revision 2")
