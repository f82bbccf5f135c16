#!/usr/bin/env bash
# The planted-harm control (issue #71; SPEC.md §21.6–21.7): the ghosting sweep — the
# hallucination grid's level none with every generation shifted as a whole by t × 8 px in
# a seeded direction — full against conflicting_views (and even_views when VARIANTS says
# so). The audit must find the primary claim (the detail ratio on contested pixels) holds.
# Seeds accumulate in the room's folder.
#
# Usage: reference_data/audit/run_control.sh DATASET A..B [UNSEEN_BINARY]
#   DATASET: a dataset folder with truth, candidates.json and evaluation.json (any room)
#   e.g. reference_data/audit/run_control.sh reference_data/scenes/gallery 0..4
# LEVELS overrides the levels (default 1; the report judges only the levels named, so name
# every level the folder holds), VARIANTS the variants (default
# full,conflicting_views), FAMILY names a candidate family of the dataset (e.g. ring-13),
# OUT the folder (default reference_data/audit/<dataset name>[-<family>]-control), ARGS more
# options of `unseen audit` (e.g. ARGS="--train-resolution 1": another preset's samples
# need a folder of their own).
# Low priority: nice 19 (a setsid batch needs its autogroup niced: run_mechanisms.sh).
set -euo pipefail
dataset="$(cd "$1" && pwd)"; seeds="$2"
cd "$(dirname "$0")/../.."
bin="${3:-target/release/unseen}"
levels="${LEVELS:-1}"
variants="${VARIANTS:-full,conflicting_views}"
name="$(basename "$dataset")${FAMILY:+-$FAMILY}"
family=()
[ -n "${FAMILY:-}" ] && family=(--candidates "$FAMILY")
out="${OUT:-reference_data/audit/$name-control}"
work="${WORK:-/tmp/unseen-control-$name}"
mkdir -p "$work" "$out"
# samples.json.gz (an older binary's folder: samples.json; the audit reads either)
cp "$out"/samples.json* "$work/" 2>/dev/null || true
# shellcheck disable=SC2086 # ARGS is a list of options
nice -n 19 "$bin" audit "$dataset" --preset quick "${family[@]}" ${ARGS:-} \
  --variants "$variants" --sweep "ghosting=$levels" \
  --seeds "$seeds" --threads 2 --out "$work"
rm -f "$out"/samples.json "$out"/samples.json.gz
cp "$work"/samples.json* "$work"/{audit.json,audit.md,inconsistency.svg} "$out/"
cp "$work"/dose-*.svg "$out/" 2>/dev/null || true
# The contact sheets audit.md shows (each primary claim's at its median seed).
{ grep -o '](sheets/[^)]*\.png)' "$work/audit.md" || true; } | sed 's/^](//; s/)$//' | while read -r f; do
  mkdir -p "$out/$(dirname "$f")" && cp "$work/$f" "$out/$f"
done
rm -rf "$work/runs" "$work/cache" "$work/original"
