#!/usr/bin/env bash
# Throughput, size and memory of `looming process` against a plain copy of the
# same log (the floor): the table of docs/performance.md. Outside CI.
#
# Usage: bash scripts/bench.sh
#   For each resolution (32 x 512, then 64 x 2048), synthesizes the
#   safe-drive scenario (60 s, 600 scans; ~1.9 GB at 64 x 2048), then times,
#   each alone:
#     copy     target/release/examples/mcap_copy IN OUT   (mcap crate, zstd
#              level 3, 4 MiB chunks: the same compression as `looming process`)
#     process  looming process IN -o OUT --force -q --json-summary S.json
#     full     the same with --fields full
#     coarse   the same with --firings-per-column 2 (the coarser image)
#   and prints Markdown tables per resolution (also written to
#   $BENCH_DIR/bench-table.md, and per resolution to $BENCH_DIR/BxC/).
#   The full run takes ~12 minutes on 2 cores and needs ~10 GB free in BENCH_DIR.
#
# First, the real logs of ../shared/real-data (BENCH_REAL_DIR; BENCH_REAL=0
# skips them): each copied and processed BENCH_REAL_RUNS times (3), medians;
# scans/s and the ratio to the copy. Every run's table ends with the time
# per pair of each stage (the run summary's `annotation.stages`).
#
# Environment:
#   BENCH_DIR       working directory (default target/bench); relative paths
#                   are taken from the repository root
#   BENCH_DURATION  drive length in seconds, passed to `synth --duration`
#                   (default: the scenario's 60 s); e.g. 10 for a quick trial
#   BENCH_KEEP=1    keep the MCAP files (by default each is deleted once measured)
#   BENCH_RESOLUTIONS  beams x columns to run (default "32x512 64x2048")
#
# Measured with /usr/bin/time -v (wall time, user + sys CPU, maximum resident
# set size), else with a Python wrapper reading the same from resource.getrusage.
# Run nothing else heavy meanwhile: the machine's cores are the benchmark.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

dir=${BENCH_DIR:-target/bench}
case $dir in /*) ;; *) dir=$root/$dir ;; esac
mkdir -p "$dir"
keep=${BENCH_KEEP:-0}
duration_args=()
if [ -n "${BENCH_DURATION:-}" ]; then
  duration_args=(--duration "$BENCH_DURATION")
fi

log() { echo "bench: $*" >&2; }

cargo build --release --bins --examples --quiet
# Run copies, so that a rebuild during the benchmark cannot swap the binaries.
mkdir -p "$dir/bin"
cp target/release/looming target/release/examples/mcap_copy \
  target/release/examples/channel_sizes "$dir/bin/"
looming=$dir/bin/looming
copy=$dir/bin/mcap_copy
sizes=$dir/bin/channel_sizes
echo "$(git rev-parse --short HEAD 2>/dev/null || echo unknown)$(git diff --quiet HEAD 2>/dev/null || echo ' (uncommitted changes)')" > "$dir/commit"

# Busy CPU seconds of the whole machine so far (/proc/stat), to tell how much
# CPU other processes took during a run.
busy() { awk -v hz="$(getconf CLK_TCK)" '/^cpu /{printf "%.2f\n", ($2+$3+$4+$7+$8+$9)/hz; exit}' /proc/stat; }

# measure NAME CMD...: run CMD, write "wall_s cpu_s maxrss_kb" to $dir/NAME.time
# and the machine's busy CPU seconds during it to $dir/NAME.busy.
if [ -x /usr/bin/time ] && /usr/bin/time -v true > /dev/null 2>&1; then
  measure() {
    local name=$1 before
    shift
    before=$(busy)
    /usr/bin/time -v -o "$dir/$name.timev" "$@"
    awk -v a="$(busy)" -v b="$before" 'BEGIN{printf "%.2f\n", a - b}' > "$dir/$name.busy"
    python3 - "$dir/$name.timev" > "$dir/$name.time" <<'PY'
import sys
v = {}
for line in open(sys.argv[1]):
    key, _, value = line.strip().rpartition(": ")
    v[key] = value
wall = 0.0
for part in v["Elapsed (wall clock) time (h:mm:ss or m:ss)"].split(":"):
    wall = wall * 60 + float(part)
cpu = float(v["User time (seconds)"]) + float(v["System time (seconds)"])
print(f"{wall:.2f} {cpu:.2f} {v['Maximum resident set size (kbytes)']}")
PY
  }
else
  log "/usr/bin/time -v not available: measuring with python3 resource"
  measure() {
    local name=$1 before
    shift
    before=$(busy)
    python3 - "$dir/$name.time" "$@" <<'PY'
import resource, subprocess, sys, time
start = time.monotonic()
code = subprocess.call(sys.argv[2:])
wall = time.monotonic() - start
r = resource.getrusage(resource.RUSAGE_CHILDREN)
if code != 0:
    sys.exit(code)
with open(sys.argv[1], "w") as f:
    f.write(f"{wall:.2f} {r.ru_utime + r.ru_stime:.2f} {r.ru_maxrss}\n")
PY
    awk -v a="$(busy)" -v b="$before" 'BEGIN{printf "%.2f\n", a - b}' > "$dir/$name.busy"
  }
fi

# table DIR BEAMS COLUMNS: the Markdown tables of one resolution's runs.
table() {
  python3 - "$1" "$(nproc)" "$2" "$3" "$root" <<'PY'
import json, sys
d, cores, beams, columns = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
SCAN_HZ = 10.0

exec(open(f"{sys.argv[5]}/scripts/bench_stages.py").read())

def read_time(name):
    wall, cpu, rss = open(f"{d}/{name}.time").read().split()
    return float(wall), float(cpu), int(rss) / 1024.0  # s, s, MiB

def read_sizes(name):
    out = {}
    for line in open(f"{d}/{name}.sizes").read().splitlines()[1:]:
        topic, raw, zstd, _share = line.split()
        out[topic] = (int(raw), int(zstd))
    return out

in_bytes = int(open(f"{d}/input.bytes").read())
summaries = {r: json.load(open(f"{d}/{r}.json")) for r in ("process", "full", "coarse")}
scans = summaries["process"]["decoded"]["scans"]
runs = [("copy (mcap crate)", "copy"), ("looming process", "process"),
        ("looming process --fields full", "full"),
        ("looming process --firings-per-column 2", "coarse")]
t = {r: read_time(r) for _, r in runs}
b = {r: int(open(f"{d}/{r}.bytes").read()) for _, r in runs}
other = {r: max(0.0, float(open(f"{d}/{r}.busy").read()) - t[r][1]) for _, r in runs}
synth_wall = read_time("synth")[0]
cw, _, crss = t["copy"]
commit = open(f"{d}/commit").read().strip()

print(f"safe-drive {beams} x {columns}, {scans} scans ({scans / SCAN_HZ:.0f} s at {SCAN_HZ:.0f} Hz), "
      f"input {in_bytes / 1e6:.0f} MB; {cores} cores; commit {commit}; synth took {synth_wall:.0f} s.")
print()
print("| run | wall s | CPU s | other CPU s | scans/s | x real time | throughput / copy | peak RSS MiB | RSS / copy | output MB | output / input |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for label, r in runs:
    wall, cpu, rss = t[r]
    sps = scans / wall
    print(f"| {label} | {wall:.1f} | {cpu:.1f} | {other[r]:.1f} | {sps:.1f} | {sps / SCAN_HZ:.2f} | "
          f"{cw / wall:.2f} | {rss:.0f} | {rss / crss:.1f} | {b[r] / 1e6:.0f} | {b[r] / in_bytes:.3f} |")
print()
print("throughput / copy: the copy's wall time over the run's (1.0 = as fast as a bare copy). "
      "Output written by: " + ", ".join(
          f"{r}: {summaries[r].get('write', {}).get('mode', '?')}" for r in ("process", "full", "coarse")) + ".")
print()
print("CPU s: user + system of the run; other CPU s: what the rest of the machine used "
      "meanwhile (/proc/stat), near 0 when the run was alone.")

print()
print("| run | pairs | events | engine_s | engine_s / wall | s per pair (wall) | bad messages | warnings |")
print("|---|---|---|---|---|---|---|---|")
for label, r in runs[1:]:
    s = summaries[r]
    a = s["annotation"]
    wall = t[r][0]
    warnings = len(s["warnings"]) + len(s["input_report"]["warnings"])
    print(f"| {label} | {s['pairs_written']} | {a['events']} | {a['engine_s']:.1f} | "
          f"{a['engine_s'] / wall:.2f} | {wall / s['pairs_written']:.3f} | {s['bad_messages']} | {warnings} |")

print()
print(stage_table([(label, summaries[r]) for label, r in runs[1:]]))

inp = read_sizes("input")
lidar = inp["/lidar/points"][1]
print()
print("Bytes per channel (channel_sizes: each channel's messages zstd-3 in 4 MiB blocks), MB:")
print()
outs = {r: read_sizes(r) for r in ("process", "full")}
topics = list(inp) + [k for k in outs["full"] if k not in inp]
print("| channel | input zstd | process zstd | full zstd |")
print("|---|---|---|---|")
for k in topics:
    cells = [inp.get(k), outs["process"].get(k), outs["full"].get(k)]
    print(f"| `{k}` | " + " | ".join("-" if c is None else f"{c[1] / 1e6:.1f}" for c in cells) + " |")
print()
print(f"| run | added (/looming/*) MB | added / LiDAR | LiDAR-only log: (LiDAR + added) / LiDAR |")
print("|---|---|---|---|")
for label, r in runs[1:3]:
    added = sum(z for k, (_, z) in outs[r].items() if k.startswith("/looming/"))
    print(f"| {label} | {added / 1e6:.0f} | {added / lidar:.3f} | {(lidar + added) / lidar:.2f} |")
print()
print(f"`/lidar/points` alone: {lidar / 1e6:.0f} MB zstd, {inp['/lidar/points'][0] / 1e6:.0f} MB raw; "
      f"`/truth/*`: {sum(z for k, (_, z) in inp.items() if k.startswith('/truth/')) / 1e6:.0f} MB zstd.")
PY
}

# One resolution: synthesize, copy, process, process --fields full, each
# measured; files in $rdir.
measure_resolution() {
  local beams=$1 columns=$2
  rdir=$dir/${beams}x${columns}
  mkdir -p "$rdir"
  cp "$dir/commit" "$rdir/commit"
  local saved_dir=$dir
  dir=$rdir
  input=$dir/safe-drive-${beams}x${columns}.mcap
  log "synthesizing $input (${beams} x ${columns}) ${duration_args[*]:-(60 s)}"
  measure synth "$looming" synth --scenario safe-drive --beams "$beams" --columns "$columns" \
    "${duration_args[@]}" -o "$input" --force -q
  stat -c %s "$input" > "$dir/input.bytes"
  "$sizes" "$input" > "$dir/input.sizes"

  log "copy (mcap crate, the floor)"
  measure copy "$copy" "$input" "$dir/copy.mcap"
  stat -c %s "$dir/copy.mcap" > "$dir/copy.bytes"
  [ "$keep" = 1 ] || rm -f "$dir/copy.mcap"

  for run in process full coarse; do
    fields=()
    [ "$run" = full ] && fields=(--fields full)
    [ "$run" = coarse ] && fields=(--firings-per-column 2)
    log "looming process ${fields[*]:-}"
    measure "$run" "$looming" process "$input" -o "$dir/$run.mcap" --force -q \
      --json-summary "$dir/$run.json" "${fields[@]}"
    stat -c %s "$dir/$run.mcap" > "$dir/$run.bytes"
    "$sizes" "$dir/$run.mcap" > "$dir/$run.sizes"
    [ "$keep" = 1 ] || rm -f "$dir/$run.mcap"
  done
  [ "$keep" = 1 ] || rm -f "$input"
  table "$dir" "$beams" "$columns" > "$dir/bench-table.md"
  dir=$saved_dir
}


# The real logs (BENCH_REAL_DIR, default ../shared/real-data beside the
# repository; skipped when absent): each copied and processed
# BENCH_REAL_RUNS times in turn (default 3), medians reported.
measure_real() {
  local real_dir=${BENCH_REAL_DIR:-$root/../shared/real-data} runs=${BENCH_REAL_RUNS:-3}
  [ -d "$real_dir" ] || { log "no real logs at $real_dir: skipped"; return; }
  local rdir=$dir/real
  mkdir -p "$rdir"
  for log_path in "$real_dir"/*.mcap; do
    local name
    name=$(basename "$log_path" .mcap)
    for k in $(seq "$runs"); do
      log "real log $name, run $k of $runs"
      measure "real/$name.copy.$k" "$copy" "$log_path" "$rdir/copy.mcap" >&2
      measure "real/$name.process.$k" "$looming" process "$log_path" -o "$rdir/process.mcap" \
        --force -q --json-summary "$rdir/$name.json" >&2
    done
    stat -c %s "$log_path" > "$rdir/$name.bytes"
  done
  rm -f "$rdir/copy.mcap" "$rdir/process.mcap"
  python3 - "$rdir" "$runs" "$root" <<'PY'
import glob, json, os, statistics, sys
d, runs, root = sys.argv[1], int(sys.argv[2]), sys.argv[3]
exec(open(f"{root}/scripts/bench_stages.py").read())
def wall(name, run, k):
    return float(open(f"{d}/{name}.{run}.{k}.time").read().split()[0])
rows, stages = [], []
for path in sorted(glob.glob(f"{d}/*.json")):
    name = os.path.basename(path)[:-5]
    s = json.load(open(path))
    scans = s["decoded"]["scans"]
    copy = statistics.median(wall(name, "copy", k) for k in range(1, runs + 1))
    proc = statistics.median(wall(name, "process", k) for k in range(1, runs + 1))
    rows.append(f"| {name} | {scans} | {copy:.2f} | {proc:.2f} | {scans / proc:.1f} | {copy / proc:.2f} |")
    stages.append((name, s))
print(f"Real logs: medians of {runs} runs each, copy and process in turn.")
print()
print("| log | scans | copy wall s | process wall s | scans/s | throughput / copy |")
print("|---|---|---|---|---|---|")
print("\n".join(rows))
print()
print(stage_table(stages))
PY
}

: > "$dir/bench-table.md"
if [ "${BENCH_REAL:-1}" = 1 ]; then
  measure_real > "$dir/real-table.md"
  cat "$dir/real-table.md" >> "$dir/bench-table.md"
  echo >> "$dir/bench-table.md"
fi
for resolution in ${BENCH_RESOLUTIONS:-32x512 64x2048}; do
  measure_resolution "${resolution%x*}" "${resolution#*x}"
  cat "$rdir/bench-table.md" >> "$dir/bench-table.md"
  echo >> "$dir/bench-table.md"
  for r in process full coarse; do
    python3 - "$rdir/$r.json" "$r" <<'PY' >&2
import json, sys
s = json.load(open(sys.argv[1]))
w = s["warnings"] + s["input_report"]["warnings"]
if w or s["bad_messages"]:
    print(f"bench: {sys.argv[2]}: {s['bad_messages']} bad messages, warnings: {w}")
PY
  done
done
cat "$dir/bench-table.md"
log "table written to $dir/bench-table.md"
