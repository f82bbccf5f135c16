#!/usr/bin/env bash
# Usage: run-all.sh [MINUTES [TARGET...]]
# Run every fuzz target (or the TARGETs given) for MINUTES each (default 30), JOBS at a
# time (default 1), on its corpus (fuzz/corpus/<target>, grown by the run, not committed)
# and the committed seeds (fuzz/seeds/<target>). Appends one line per target to fuzz/runs.log:
#   date target minutes executions exit-status
# and leaves any crashing input under fuzz/artifacts/<target>/ (turn each into a test in
# tests/engine/, see fuzz/README.md).
#
# Needs cargo-fuzz (`cargo install cargo-fuzz`) and libFuzzer's compiler flags: nightly, or
# the stable compiler with RUSTC_BOOTSTRAP=1 (set here when the toolchain is not nightly).
set -euo pipefail
cd "$(dirname "$0")"
MINUTES="${1:-30}"
shift || true
JOBS="${JOBS:-1}"
if ! rustc --version | grep -q nightly; then
    export RUSTC_BOOTSTRAP=1
fi
cargo fuzz build
mkdir -p logs
run_one() {
    local t="$1"
    mkdir -p "corpus/$t" "seeds/$t"
    local log="logs/$t.log"
    local status=0
    # The targets that feed path readers write their inputs under TMPDIR: a fresh one per
    # run, removed after.
    local scratch
    scratch="$(mktemp -d)"
    TMPDIR="$scratch" cargo fuzz run "$t" "corpus/$t" "seeds/$t" -- \
        -max_total_time=$((MINUTES * 60)) -rss_limit_mb=2048 -max_len=65536 \
        -print_final_stats=1 >"$log" 2>&1 || status=$?
    rm -rf "$scratch"
    local execs
    execs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "$log" | awk '{print $2}' | tail -1)
    echo "$(date -u +%Y-%m-%dT%H:%MZ) $t $MINUTES ${execs:-?} $status" >>runs.log
    echo "$t: ${execs:-?} executions, exit $status"
}
export -f run_one
export MINUTES
if [ $# -gt 0 ]; then printf '%s\n' "$@"; else cargo fuzz list; fi |
    xargs -P "$JOBS" -I{} bash -c 'run_one {}'
