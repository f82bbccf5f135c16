#!/usr/bin/env bash
# The audit of the paper's central mechanism with the comparisons that isolate it
# (issue #54; reference_data/audit/<room>-isolation/): under the mechanisms generator
# (truth-low+hallucinating+relative), full against even_views (the paper's ablation),
# conflicting_views (a colliding set of the same size at matched coverage),
# no_depth_supervision, the cycle the paper replaces, and the independent-views claim under
# the other selection rules and the hull outline (the *_max_cardinality, *_max_coverage and
# *_hull pairs); every run records its diagnostics (SPEC.md §21.5).
# Seeds accumulate: each batch adds to the folder's samples.json.gz.
#
# Usage: reference_data/audit/run_isolation.sh ROOM A..B [UNSEEN_BINARY]
#   e.g. reference_data/audit/run_isolation.sh lounge 0..2
# The default variants are every variant the committed <room>-isolation/ folder holds (its
# report shows the claims of the variants asked for, so a shorter list drops claims from
# it); jobs already pooled as this binary computes them are not run again, so the full list
# costs only what is new. VARIANTS overrides the list.
# FAMILY names a candidate family of the room (SPEC.md §20.7, e.g. FAMILY=ring-13): the
# pipeline is given it instead of the bridge views, into reference_data/audit/<room>-<family>/
# (default variants there: full, even_views, conflicting_views, as committed).
# Low priority: see run_mechanisms.sh (nice 19; a setsid batch needs its autogroup niced).
set -euo pipefail
cd "$(dirname "$0")/../.."
room="$1"; seeds="$2"; bin="${3:-target/release/unseen}"
# ROOM is a bundled room's name or any dataset folder with truth, candidates.json and
# evaluation.json (absolute, or from the repository's root): its folder name names the output.
dataset="reference_data/scenes/$room"
if [ -d "$room" ]; then dataset="$room"; room="$(basename "$(cd "$room" && pwd)")"; fi
all=full,even_views,conflicting_views,no_depth_supervision,cycle
all+=,full_max_cardinality,even_views_max_cardinality,full_max_coverage
all+=,even_views_max_coverage,full_hull,even_views_hull
variants="${VARIANTS:-${FAMILY:+full,even_views,conflicting_views}}"
variants="${variants:-$all}"
family=()
out="reference_data/audit/$room-isolation"
if [ -n "${FAMILY:-}" ]; then
  family=(--candidates "$FAMILY")
  out="reference_data/audit/$room-$FAMILY"
fi
work="${WORK:-/tmp/unseen-isolation-$room${FAMILY:+-$FAMILY}}"
mkdir -p "$work" "$out"
# samples.json.gz (an older binary's folder: samples.json; the audit reads either)
cp "$out"/samples.json* "$work/" 2>/dev/null || true
nice -n 19 "$bin" audit "$dataset" --preset quick "${family[@]}" \
  --variants "$variants" --generators truth-low+hallucinating+relative \
  --seeds "$seeds" --threads 2 --out "$work"
rm -f "$out"/samples.json "$out"/samples.json.gz
cp "$work"/samples.json* "$work"/{audit.json,audit.md,inconsistency.svg} "$out/"
rm -rf "$work/runs" "$work/cache" "$work/original"
