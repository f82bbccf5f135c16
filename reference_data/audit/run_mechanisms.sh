#!/usr/bin/env bash
# The revision-6 audit of the paper's mechanisms (reference_data/audit/<room>-mechanisms/):
# the main claims (independent views, depth supervision, video depth for the dependent
# views) under the classical slots, the ground-truth generator at the low level, and the
# same hallucinating unseen content with relative depth. Seeds accumulate: each batch adds
# to the folder's samples.json.gz.
#
# Usage: reference_data/audit/run_mechanisms.sh ROOM A..B [UNSEEN_BINARY]
#   e.g. reference_data/audit/run_mechanisms.sh gallery 6..8
# The binary must be of numerics revision 6 (a release build of this tree); a batch of two
# seeds of one room takes 20–30 min on 2 cores at nice 19. The run folders (≈1 GB a seed)
# are removed after a batch that succeeded: samples.json.gz is what the audit keeps.
# Low priority: `nice 19` yields only within this session's scheduler autogroup; a batch
# started with `setsid` is its own group and gets an equal share of the cores unless its
# group is niced too: `echo 19 > /proc/<pid>/autogroup` (benches/README.md).
set -euo pipefail
cd "$(dirname "$0")/../.."
room="$1"; seeds="$2"; bin="${3:-target/release/unseen}"
out="reference_data/audit/$room-mechanisms"
work="${WORK:-/tmp/unseen-audit-$room}"
mkdir -p "$work"
# samples.json.gz (an older binary's folder: samples.json; the audit reads either)
cp "$out"/samples.json* "$work/" 2>/dev/null || true
nice -n 19 "$bin" audit "reference_data/scenes/$room" --preset quick \
  --variants full,even_views,no_depth_supervision,stage2_render_fit \
  --generators classical,truth-low,truth-low+hallucinating+relative \
  --seeds "$seeds" --threads 2 --out "$work"
rm -f "$out"/samples.json "$out"/samples.json.gz
cp "$work"/samples.json* "$work"/{audit.json,audit.md,inconsistency.svg} "$out/"
rm -rf "$work/runs" "$work/cache" "$work/original"
