#!/usr/bin/env bash
# The training half, stage by stage (issue #72; SPEC.md §20.7's lineage, §21.5's stage
# records): the pipeline under four generators — perfect (truth-none), consistent
# (truth-low), classical, hallucinating — as the paper runs it (`full`) and with the
# generated views dropped from every reconstruction (`originals_only`, the recipe's
# control) and with the QA-Mask replaced by none or the opacity mask (`no_qa_mask`,
# `opacity_mask`: the mask's own share), quick preset. audit.md's "The training half per stage" holds the table.
# Seeds accumulate in the room's folder.
#
# Usage: reference_data/audit/run_training_half.sh DATASET A..B [UNSEEN_BINARY]
#   DATASET: a dataset folder with truth, candidates.json and evaluation.json (any room)
#   e.g. reference_data/audit/run_training_half.sh reference_data/scenes/gallery 0..2
# GENERATORS and VARIANTS override the lists (name every one the folder holds: the report
# judges only those named), OUT the folder (default
# reference_data/audit/<dataset name>-training-half), ARGS more options of `unseen audit`,
# CONFIG a pipeline configuration's overrides (default: the attribution on, SPEC.md §20.5 —
# which views' gradients moved the Gaussians; a record that pools with runs made without).
# Low priority: nice 19 (a setsid batch needs its autogroup niced: run_mechanisms.sh).
set -euo pipefail
dataset="$(cd "$1" && pwd)"; seeds="$2"
cd "$(dirname "$0")/../.."
bin="${3:-target/release/unseen}"
generators="${GENERATORS:-truth-none,truth-low,classical,truth-low+hallucinating+relative}"
variants="${VARIANTS:-full,originals_only,no_qa_mask,opacity_mask}"
name="$(basename "$dataset")"
out="${OUT:-reference_data/audit/$name-training-half}"
work="${WORK:-/tmp/unseen-training-half-$name}"
mkdir -p "$work" "$out"
config="${CONFIG:-$work/attribution.json}"
[ -n "${CONFIG:-}" ] || echo '{"attribution": true}' > "$config"
cp "$out"/samples.json* "$work/" 2>/dev/null || true
# shellcheck disable=SC2086 # ARGS is a list of options
nice -n 19 "$bin" audit "$dataset" --preset quick --config "$config" ${ARGS:-} \
  --generators "$generators" \
  --variants "$variants" --seeds "$seeds" --threads 2 --out "$work"
rm -f "$out"/samples.json "$out"/samples.json.gz
cp "$work"/samples.json* "$work"/{audit.json,audit.md,inconsistency.svg} "$out/"
rm -rf "$work/runs" "$work/cache" "$work/original"
