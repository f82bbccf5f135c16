#!/usr/bin/env bash
# The audit of the paper's central mechanism with the comparisons that isolate it
# (issue #54; reference_data/audit/<room>-isolation/): under the mechanisms generator
# (truth-low+hallucinating+relative), full against even_views (the paper's ablation),
# conflicting_views (a colliding set of the same size at matched coverage), and
# no_depth_supervision; every run records its diagnostics (SPEC.md §21.5).
# Seeds accumulate: each batch adds to the folder's samples.json.
#
# Usage: reference_data/audit/run_isolation.sh ROOM A..B [UNSEEN_BINARY]
#   e.g. reference_data/audit/run_isolation.sh lounge 0..2
# VARIANTS overrides the variant list (e.g. VARIANTS=full,even_views,conflicting_views,cycle).
# Low priority: see run_mechanisms.sh (nice 19; a setsid batch needs its autogroup niced).
set -euo pipefail
cd "$(dirname "$0")/../.."
room="$1"; seeds="$2"; bin="${3:-target/release/unseen}"
variants="${VARIANTS:-full,even_views,conflicting_views,no_depth_supervision}"
out="reference_data/audit/$room-isolation"
work="${WORK:-/tmp/unseen-isolation-$room}"
mkdir -p "$work" "$out"
cp "$out/samples.json" "$work/" 2>/dev/null || true
nice -n 19 "$bin" audit "reference_data/scenes/$room" --preset quick \
  --variants "$variants" --generators truth-low+hallucinating+relative \
  --seeds "$seeds" --threads 2 --out "$work"
cp "$work"/{samples.json,audit.json,audit.md,inconsistency.svg} "$out/"
rm -rf "$work/runs" "$work/cache" "$work/original"
