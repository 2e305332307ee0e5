#!/usr/bin/env bash
# The classic-baseline tables of docs/method.md ("Against the classic baseline"): the time to contact
# of the nearest points in the ego lane (examples/baseline_ttc.rs) beside
# looming's own near misses (`looming process --events`), on the synthetic
# scenarios (against their analytic truth) and on the real KITTI logs
# (against the rear-face reference of examples/face_probe.rs).
# Outside CI (a few minutes). Honours CARGO_TARGET_DIR (default target/).
# Usage: scripts/baseline.sh [BEAMS COLUMNS]
# The KITTI logs are read where they are (LOOMING_REAL_DATA, default
# ../shared/real-data beside the repository; non-commercial: never copied into the repository).
set -euo pipefail
cd "$(dirname "$0")/.."
beams=${1:-32}
columns=${2:-512}
target=${CARGO_TARGET_DIR:-target}
real=${LOOMING_REAL_DATA:-../shared/real-data}
cargo build --release --quiet --example baseline_ttc --bin looming
looming=$target/release/looming
baseline=$target/release/examples/baseline_ttc
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

# One log: looming's events (process) and the baseline (JSON), into $out/NAME.*
measure() {
  local name=$1 log=$2
  "$looming" process "$log" -o "$out/$name.looming.mcap" --events "$out/$name.events.json" --force -q
  "$baseline" "$log" --json "$out/$name.baseline.json" > "$out/$name.baseline.md"
}

# Windows containing every planted near miss (cut-in 2.90-3.90 s, crossing
# 1.60-2.60 and 2.90-4.20 s); the others as scripts/accuracy.sh.
scenarios=("straight-road 0 2" "urban-turn 0 2" "follow 0 2" "cut-in 2 4" "crossing 0 5" "safe-drive 0 3")
for spec in "${scenarios[@]}"; do
  set -- $spec
  "$looming" synth --scenario "$1" --start "$2" --duration "$3" --beams "$beams" --columns "$columns" -o "$out/$1.mcap" --force -q
  measure "$1" "$out/$1.mcap"
done

echo "Synthetic scenarios, ${beams} x ${columns}, seed 1. Times are drive times (s); TTC in s; errors in 1/s."
echo
python3 - "$out" "$beams" "$columns" "${scenarios[@]}" <<'PY'
import json, sys
out, beams, columns, specs = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
START_NS = 1_700_000_000_000_000_000

def fmt(v, d=2):
    return "-" if v is None else f"{v:.{d}f}"

def overlaps(a_start, a_end, planted):
    return a_start < planted["end_s"] and planted["start_s"] < a_end

def found(events, planted):
    """Per planted window: the first overlapping event (one event may cover
    several windows); then the events outside every window."""
    cells, used = [], set()
    for p in planted:
        i = next((i for i, e in enumerate(events) if overlaps(e[0], e[1], p)), None)
        if i is None:
            cells.append("missed")
        elif i in used:
            cells.append(f"in the {events[i][0]:.2f} event")
        else:
            cells.append(f"{events[i][0]:.2f} ({events[i][2]:.2f})")
            used.add(i)
    extra = [e for e in events if not any(overlaps(e[0], e[1], p) for p in planted)]
    if extra:
        cells.append("false: " + ", ".join(f"{e[0]:.2f} ({e[2]:.2f})" for e in extra))
    return "; ".join(cells) if cells else "none"

print(f"| scenario ({beams} x {columns}) | window s | planted (start-end, min TTC) | looming: found (start (min TTC)) | baseline: found (start (min TTC)) | baseline false events | baseline \\|error\\| vs truth median / p90 | looming object \\|error\\|, same pairs, median / p90 |")
print("|---|---|---|---|---|---|---|---|")
for spec in specs:
    name, start, duration = spec.split()
    b = json.load(open(f"{out}/{name}.baseline.json"))["summary"]
    ev = json.load(open(f"{out}/{name}.events.json"))["events"]
    ev.sort(key=lambda e: e["start_ns"])
    looming = [((e["start_ns"] - START_NS) * 1e-9, (e["end_ns"] - START_NS) * 1e-9, e["min_time_to_contact_s"]) for e in ev]
    base = [(e["start_s"], e["end_s"], e["min_ttc_s"]) for e in b["baseline_events"]]
    planted = b["planted"]
    planted_cell = "; ".join(f"{p['start_s']:.2f}-{p['end_s']:.2f} ({p['min_ttc_s']:.2f})" for p in planted) or "none"
    be, bc, lc = b["baseline_error"], b["baseline_error_common"], b["looming_object_error_common"]
    print(f"| {name} | {start}-{duration} | {planted_cell} | {found(looming, planted)} | {found(base, planted)} "
          f"| {b['baseline_false_events']} | {fmt(be['median_per_s'], 3)} / {fmt(be['p90_per_s'], 3)} ({be['pairs']} pairs) "
          f"| {fmt(lc['median_per_s'], 3)} / {fmt(lc['p90_per_s'], 3)} ({lc['pairs']} pairs; baseline there {fmt(bc['median_per_s'], 3)} / {fmt(bc['p90_per_s'], 3)}) |")
PY

kitti=()
for name in kitti-braking-78-scans-lidar-only kitti-22-scans-lidar-only; do
  if [ -f "$real/$name.mcap" ]; then
    measure "$name" "$real/$name.mcap"
    kitti+=("$name")
  else
    echo "skipped: $real/$name.mcap not found" >&2
  fi
done
[ ${#kitti[@]} -eq 0 ] && exit 0
echo
echo "Real KITTI logs (LiDAR only, no truth): reference = the rear face of examples/face_probe.rs. Errors in 1/s."
echo
python3 - "$out" "${kitti[@]}" <<'PY'
import json, sys
out, names = sys.argv[1], sys.argv[2:]
def fmt(v, d=3):
    return "-" if v is None else f"{v:.{d}f}"
def events(list_):
    return f"{len(list_)}" + ("" if not list_ else ": " + ", ".join(f"{s:.1f} s ({t:.2f})" for s, t in list_))
print("| log | pairs (baseline / reference) | smallest reference TTC s | baseline \\|error\\| median / p90 | looming object \\|error\\|, same pairs, median / p90 | baseline events (start, min TTC) | looming events (start, min TTC) |")
print("|---|---|---|---|---|---|---|")
for name in names:
    b = json.load(open(f"{out}/{name}.baseline.json"))["summary"]
    ev = json.load(open(f"{out}/{name}.events.json"))["events"]
    # looming's events in the baseline's time: from the log's first scan.
    looming = [((e["start_ns"] - b["time_origin_ns"]) * 1e-9, e["min_time_to_contact_s"]) for e in ev]
    be, bc, lc = b["baseline_error"], b["baseline_error_common"], b["looming_object_error_common"]
    base = [(e["start_s"], e["min_ttc_s"]) for e in b["baseline_events"]]
    print(f"| {name} | {b['pairs_with_baseline']} / {b['pairs_with_reference']} of {b['pairs']} | {fmt(b['min_reference_ttc_s'], 2)} "
          f"| {fmt(be['median_per_s'], 4)} / {fmt(be['p90_per_s'], 4)} ({be['pairs']} pairs) "
          f"| {fmt(lc['median_per_s'], 4)} / {fmt(lc['p90_per_s'], 4)} ({lc['pairs']} pairs; baseline there {fmt(bc['median_per_s'], 4)} / {fmt(bc['p90_per_s'], 4)}) "
          f"| {events(base)} | {events(sorted(looming))} |")
PY
