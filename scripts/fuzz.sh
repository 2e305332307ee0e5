#!/usr/bin/env bash
# Fuzz every target (or those named) for SECONDS each, one at a time, with
# cargo-fuzz on the stable toolchain (--sanitizer none: no nightly needed),
# and print per target the executions, their rate, the coverage and the
# findings. Outside CI; CI replays the committed corpora (tests/fuzz_corpus.rs).
#
# Usage: bash scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]   (default 60, all)
#
# Bounds: a single allocation above 512 MB (-malloc_limit_mb), a resident set
# above 2 GB (-rss_limit_mb) or an input running over 10 s (-timeout) is a
# finding, saved under fuzz/artifacts/<target>/. The committed seeds are in
# fuzz/corpus/<target>/; the run's growing corpus in fuzz/corpus-run/<target>/
# (not committed); the MCAP targets also start from the conformance suite.
# Add a finding as a regression: fix it, then copy the artifact to
# fuzz/regressions/<target>/ (tests/fuzz_corpus.rs replays it in CI).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(mcap_indexed mcap_linear pointcloud2 foxglove_pointcloud imu twist odometry tf kitti scenario_json)
fi
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --locked
(cd fuzz && cargo fuzz build --sanitizer none -O >/dev/null)
printf '%-20s %12s %10s %8s %8s %s\n' target executions exec/s cov ft findings
for target in "${targets[@]}"; do
    run="fuzz/corpus-run/$target"
    mkdir -p "$run" "fuzz/artifacts/$target"
    extra=()
    case $target in mcap_*) extra=(tests/conformance/data/*/) ;; esac
    log=$(mktemp)
    status=0
    fuzz/target/x86_64-unknown-linux-gnu/release/"$target" "$run" "fuzz/corpus/$target" "${extra[@]}" \
        -max_total_time="$seconds" -malloc_limit_mb=512 -rss_limit_mb=2048 -timeout=10 \
        -artifact_prefix="fuzz/artifacts/$target/" -print_final_stats=1 >"$log" 2>&1 || status=$?
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
    rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
    last=$(grep -E '#[0-9]+.*cov:' "$log" | tail -1)
    cov=$(echo "$last" | grep -o 'cov: [0-9]*' | grep -o '[0-9]*' || echo "?")
    ft=$(echo "$last" | grep -o 'ft: [0-9]*' | grep -o '[0-9]*' || echo "?")
    findings=$(ls "fuzz/artifacts/$target" | wc -l)
    note=""
    [ "$status" -ne 0 ] && note=" (exit $status: $(grep -m1 -E 'ERROR|panicked|out-of-memory|timeout' "$log" || true))"
    printf '%-20s %12s %10s %8s %8s %s%s\n' "$target" "$execs" "$rate" "$cov" "$ft" "$findings" "$note"
    cp "$log" "fuzz/artifacts/$target.log"
    rm -f "$log"
done
