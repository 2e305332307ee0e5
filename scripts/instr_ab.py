#!/usr/bin/env python3
"""Two builds of `looming` against each other by the instructions they
execute (valgrind's callgrind), per stage: a measure that does not move with
the machine. Outside CI.

usage: python3 scripts/instr_ab.py OLD_BIN NEW_BIN LOG.mcap [--keep DIR]

Each build runs `process LOG` once under `valgrind --tool=callgrind` with
RAYON_NUM_THREADS=1, the two at once (each on one core: the counts do not
depend on what else runs). Printed: the instructions of the whole run and
of each stage's function, inclusive of everything it calls, for both builds
and NEW / OLD, and whether the outputs are byte-identical.

Why: the engine is bound by its instruction count (3-4 a cycle,
docs/performance.md), and the machine is shared: in whole runs a step
under 5 % on one stage is within what the machine and the code's layout
move a stage by (the same build against a copy of itself: 1.6 %), so such
steps took many alternating rounds of `bench_ab.py`. The same binary, log
and environment give the same counts to the instruction. What counts miss:
cache misses and how well a stage's instructions overlap, so a step is
still timed with `bench_ab.py` before it is kept.

Callgrind runs some 35 times slower than the binary: pick a short log (a 4
scan synthetic drive at 64 x 2048 takes 15 s, 22 KITTI scans about two
minutes); note that the first scans of a log estimate the lasers' offsets
every scan (later one scan in ten), so a log of a few scans overweights
`bias::estimate`.
"""

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile

# The outputs' hash as bench_ab.py takes it (the script's own directory is
# on the path when it is run).
from bench_ab import sha256

# The functions reported, each inclusive of its callees (so a function and
# one it calls overlap: `warp::render` holds the motion estimate's renders).
STAGE_FUNCTIONS = [
    ("range image", "looming_core::engine::grid::RangeImage::build"),
    ("lasers' offsets", "looming_core::engine::bias::estimate"),
    ("plane fits (surfaces)", "looming_core::engine::surface::Surfaces::estimate"),
    ("motion estimate", "looming_core::engine::egomotion::estimate_motion"),
    ("renders (warp::render)", "looming_core::engine::warp::render"),
    ("rotation render", "looming_core::engine::warp::render_rotation"),
    ("per cell", "looming_core::engine::cells::per_cell"),
    ("objects", "looming_core::objects::PairObjects::find_tracked_fused"),
    ("quality", "looming::quality::PairQuality::measure_on_ground"),
    ("events", "looming_core::events::EventDetector::observe"),
    ("annotation (all)", "looming::annotate::Annotator::complete"),
    ("read and decode", "looming::pipeline::stages::read_and_decode"),
    ("compress our chunks", "looming::output::chunk::compress"),
]

LINE = re.compile(r"^\s*([\d,]+)\s+\([^)]*\)\s+(?:\S*?:)?(.+?)\s+\[")


def run_callgrind(binary, log, out, profile):
    """Starts `binary process log` under callgrind; returns the process."""
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    command = [
        "valgrind", "--tool=callgrind", f"--callgrind-out-file={profile}",
        binary, "process", log, "-o", out, "--force", "-q",
    ]
    return subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


def inclusive_counts(profile):
    """{function: inclusive instructions} and the run's total."""
    text = subprocess.run(
        ["callgrind_annotate", "--inclusive=yes", "--threshold=100", profile],
        check=True, capture_output=True, text=True,
    ).stdout
    counts, total = {}, None
    for line in text.splitlines():
        if "PROGRAM TOTALS" in line:
            total = int(line.split()[0].replace(",", ""))
            continue
        match = LINE.match(line)
        if match:
            # The first (largest) line of a name; recursion's `'2` lines differ.
            counts.setdefault(match.group(2), int(match.group(1).replace(",", "")))
    if not total:
        sys.exit(f"{profile}: callgrind_annotate printed no PROGRAM TOTALS")
    return counts, total


def millions(count):
    return "-" if count is None else f"{count / 1e6:,.1f}"


def table(log, counts, totals, identical):
    old, new = counts["old"], counts["new"]
    lines = [
        f"### {os.path.basename(log)}: "
        + ("byte-identical" if identical else "outputs differ"),
        "",
        "| function (inclusive) | old, M instructions | new | new / old |",
        "|---|---|---|---|",
        f"| whole run | {totals['old'] / 1e6:,.1f} | {totals['new'] / 1e6:,.1f} | "
        f"{totals['new'] / totals['old']:.4f} |",
    ]
    for label, function in STAGE_FUNCTIONS:
        a, b = old.get(function), new.get(function)
        if a is None and b is None:
            continue
        ratio = f"{b / a:.4f}" if a and b is not None else "-"
        name = function.split("::", 1)[1]
        lines.append(f"| {label} (`{name}`) | {millions(a)} | {millions(b)} | {ratio} |")
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("old")
    parser.add_argument("new")
    parser.add_argument("log")
    parser.add_argument("--keep", help="keep the outputs and callgrind profiles here")
    args = parser.parse_args()
    for tool in ("valgrind", "callgrind_annotate"):
        if shutil.which(tool) is None:
            sys.exit(f"{tool} not found: install valgrind (Debian: apt-get install valgrind)")
    for path in (args.old, args.new, args.log):
        if not os.path.isfile(path):
            sys.exit(f"{path}: no such file")
    binaries = {"old": os.path.abspath(args.old), "new": os.path.abspath(args.new)}
    with tempfile.TemporaryDirectory() as scratch:
        work = args.keep or scratch
        os.makedirs(work, exist_ok=True)
        paths = {label: (os.path.join(work, f"{label}.mcap"),
                         os.path.join(work, f"callgrind.{label}.out")) for label in binaries}
        running = {label: run_callgrind(binaries[label], args.log, *paths[label])
                   for label in binaries}
        for label, process in running.items():
            _, stderr = process.communicate()
            if process.returncode != 0:
                sys.exit(f"{label} build failed under callgrind:\n{stderr[-2000:]}")
        counts, totals = {}, {}
        for label in binaries:
            counts[label], totals[label] = inclusive_counts(paths[label][1])
        identical = sha256(paths["old"][0]) == sha256(paths["new"][0])
        print("callgrind, RAYON_NUM_THREADS=1; instructions inclusive of callees, "
              "so rows overlap.\n")
        print(table(args.log, counts, totals, identical))


if __name__ == "__main__":
    main()
