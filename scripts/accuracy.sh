#!/usr/bin/env bash
# The accuracy table of docs/method.md: synthesize the scenarios, run
# `looming eval` on each, print one Markdown row per scenario.
# Outside CI (about a minute). Usage: scripts/accuracy.sh [BEAMS COLUMNS]
# LIDARS=3 scripts/accuracy.sh 64 2048: the vehicle with three LiDARs (synth
# --lidars 3; BEAMS x COLUMNS is the roof's, the side sensors 32 x 1024 at
# 20 Hz), a row per sensor. FRAME=vehicle|world: the clouds written in that
# frame (synth --frame), for the sensor-origin check. FIRINGS=2: the
# coarser range image of `process --firings-per-column 2`.
set -euo pipefail
cd "$(dirname "$0")/.."
beams=${1:-32}
columns=${2:-512}
lidars=${LIDARS:-1}
frame=${FRAME:-sensor}
firings=${FIRINGS:-1}
if [ "$lidars" -gt 1 ]; then
  topics="/lidar_roof/points /lidar_left/points /lidar_right/points"
  topics=$(echo $topics | cut -d' ' -f1-"$lidars")
else
  topics="auto"
fi
cargo build --release --quiet
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "| scenario (${beams} x ${columns}) | window s | pairs | L_lidar median / p90 | D p90 static (road, facing, oblique) | L_ego rel. median | RMSE fused / L_lidar / L_ray_ego | moving P / R / F1 |"
echo "|---|---|---|---|---|---|---|---|"
for spec in "straight-road 0 2" "urban-turn 0 2" "follow 0 2" "cut-in 2 4" "crossing 3 5" "safe-drive 0 3"; do
  set -- $spec
  ./target/release/looming synth --scenario "$1" --start "$2" --duration "$3" --beams "$beams" --columns "$columns" --lidars "$lidars" --frame "$frame" -o "$out/$1.mcap" --force -q
  for topic in $topics; do
  name="$1"
  if [ "$topic" = auto ]; then
    ./target/release/looming eval "$out/$1.mcap" --firings-per-column "$firings" --json "$out/$1.json" > /dev/null
  else
    name="$1 ${topic%/points}"
    ./target/release/looming eval "$out/$1.mcap" --firings-per-column "$firings" --lidar-topic "$topic" --json "$out/$1.json" > /dev/null
  fi
  python3 - "$out/$1.json" "$name" "$2-$3" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
e = r["errors"]
def s(q, c, k, digits=3):
    v = e.get(q, {}).get(c, {}).get(k)
    return "-" if v is None else f"{v:.{digits}f}"
d = r["moving_detection"]
f = lambda v: "-" if v is None or v != v else f"{v:.3f}"
print(f"| {sys.argv[2]} | {sys.argv[3]} | {r['pairs']} | {s('l_lidar','all_unmasked','median_abs')} / {s('l_lidar','all_unmasked','p90_abs')} "
      f"| {s('disagreement','static_road','p90_abs')}, {s('disagreement','static_facing','p90_abs')}, {s('disagreement','static_oblique','p90_abs')} "
      f"| {float(e['l_ego_relative']['static_points']['median_abs'])*100:.2f} % "
      f"| {s('fused','all_unmasked','rmse',4)} / {s('l_lidar','all_unmasked','rmse',4)} / {s('l_ray_ego','all_unmasked','rmse',4)} "
      f"| {f(d['precision'])} / {f(d['recall'])} / {f(d['f1'])} |")
PY
  done
done
