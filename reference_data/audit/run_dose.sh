#!/usr/bin/env bash
# The dose–response audit (issue #54; reference_data/audit/<room>-dose-<param>/): the
# mechanisms generator with one parameter swept from none to full (SPEC.md §21.6), full
# against even_views and conflicting_views at every level. Seeds accumulate.
#
# Usage: reference_data/audit/run_dose.sh ROOM PARAM A..B [UNSEEN_BINARY]
#   PARAM: hallucination, photometric or depth_distortion
#   e.g. reference_data/audit/run_dose.sh lounge hallucination 0..2
# LEVELS overrides the levels (default 0,0.25,0.5,0.75,1; the report judges only the levels
# named, so name every level the folder holds). FAMILY names a candidate family
# of the room (SPEC.md §20.7, e.g. FAMILY=ring-13: the lounge's bridge views rarely give a
# colliding set that qualifies), into reference_data/audit/<room>-<family>-dose-<param>/.
# OUT names another folder (e.g. a re-run with the panel beside an earlier revision's), ARGS
# more options of `unseen audit` (e.g. ARGS="--train-resolution 1").
set -euo pipefail
cd "$(dirname "$0")/../.."
room="$1"; param="$2"; seeds="$3"; bin="${4:-target/release/unseen}"
# ROOM is a bundled room's name or any dataset folder with truth, candidates.json and
# evaluation.json (absolute, or from the repository's root): its folder name names the output.
dataset="reference_data/scenes/$room"
if [ -d "$room" ]; then dataset="$room"; room="$(basename "$(cd "$room" && pwd)")"; fi
levels="${LEVELS:-0,0.25,0.5,0.75,1}"
family=()
out="reference_data/audit/$room-dose-$param"
if [ -n "${FAMILY:-}" ]; then
  family=(--candidates "$FAMILY")
  out="reference_data/audit/$room-$FAMILY-dose-$param"
fi
out="${OUT:-$out}"
work="${WORK:-/tmp/unseen-dose-$room${FAMILY:+-$FAMILY}-$param}"
mkdir -p "$work" "$out"
# samples.json.gz (an older binary's folder: samples.json; the audit reads either)
cp "$out"/samples.json* "$work/" 2>/dev/null || true
# shellcheck disable=SC2086 # ARGS is a list of options
nice -n 19 "$bin" audit "$dataset" --preset quick "${family[@]}" ${ARGS:-} \
  --variants full,even_views,conflicting_views --sweep "$param=$levels" \
  --seeds "$seeds" --threads 2 --out "$work"
rm -f "$out"/samples.json "$out"/samples.json.gz
cp "$work"/samples.json* "$work"/{audit.json,audit.md,inconsistency.svg} "$work"/dose-*.svg "$out/"
# The contact sheets audit.md shows (each primary claim's at its median seed).
{ grep -o '](sheets/[^)]*\.png)' "$work/audit.md" || true; } | sed 's/^](//; s/)$//' | while read -r f; do
  mkdir -p "$out/$(dirname "$f")" && cp "$work/$f" "$out/$f"
done
rm -rf "$work/runs" "$work/cache" "$work/original"
