#!/usr/bin/env python3
"""Two builds of `looming` against each other on the same logs, in
alternating runs: the A/B measurement of docs/performance.md's steps (the
machine is shared and noisy, so a step is judged against the build before it
measured minutes apart, never against a figure from another day). Outside CI.

usage: python3 scripts/bench_ab.py OLD_BIN NEW_BIN LOG.mcap... [--runs N]
                                   [--threads T] [--keep DIR]

For each log, N rounds (default 3) of `OLD process` then `NEW process`
(`--force -q --json-summary`), each alone. Per build: wall seconds, CPU
seconds (user + system of the run) and every engine stage's seconds from the
run summary (`annotation.stages`), as medians with the runs' spread, and
NEW / OLD of the medians. The first round's outputs are hashed: "byte-identical"
says whether NEW wrote the same file as OLD (an exact step), else "outputs
differ" (a step that must be checked on the accuracy tables and the real
logs).

--threads T sets RAYON_NUM_THREADS (1: one thread, the stages' CPU; unset:
both cores, what a user waits for). --keep DIR keeps the outputs there.
"""

import argparse
import hashlib
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

# The stages' keys and labels of bench.sh's table (the script's own
# directory is on the path when it is run).
from bench_stages import STAGES


def children_cpu_s():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_once(binary, log, out, summary, env):
    """One `process` run: (wall s, CPU s, the run summary)."""
    cpu_before = children_cpu_s()
    start = time.perf_counter()
    subprocess.run(
        [binary, "process", log, "-o", out, "--force", "-q", "--json-summary", summary],
        check=True,
        env=env,
    )
    wall_s = time.perf_counter() - start
    cpu_s = children_cpu_s() - cpu_before
    with open(summary) as f:
        return wall_s, cpu_s, json.load(f)


def sha256(path):
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def spread(values):
    """Median and the runs' range, as text."""
    return f"{statistics.median(values):.3f} ({min(values):.3f}-{max(values):.3f})"


def ratio(new, old):
    old_median = statistics.median(old)
    return f"{statistics.median(new) / old_median:.3f}" if old_median > 0 else "-"


def measure_log(log, binaries, runs, env, work):
    """Per build label: {'wall': [...], 'cpu': [...], stage key: [...]},
    and whether the first round's outputs are byte-identical."""
    results = {label: {"wall": [], "cpu": []} for label, _ in binaries}
    hashes = {}
    name = os.path.splitext(os.path.basename(log))[0]
    for round_index in range(runs):
        for label, binary in binaries:
            out = os.path.join(work, f"{name}-{label}.mcap")
            summary = os.path.join(work, f"{name}-{label}.json")
            wall_s, cpu_s, report = run_once(binary, log, out, summary, env)
            measured = results[label]
            measured["wall"].append(wall_s)
            measured["cpu"].append(cpu_s)
            stages = report.get("annotation", {}).get("stages", {})
            for key, _ in STAGES:
                measured.setdefault(key, []).append(stages.get(key, 0.0))
            if round_index == 0:
                hashes[label] = sha256(out)
            print(f"  {name} round {round_index + 1} {label}: wall {wall_s:.2f} s, "
                  f"CPU {cpu_s:.2f} s", file=sys.stderr)
    return results, hashes["old"] == hashes["new"]


def table(name, results, identical):
    old, new = results["old"], results["new"]
    lines = [
        f"### {name}: " + ("byte-identical" if identical else "outputs differ"),
        "",
        "| measure | old: median (range) | new: median (range) | new / old |",
        "|---|---|---|---|",
    ]
    rows = [("wall s", "wall"), ("CPU s", "cpu")]
    rows += [(f"{label} s", key) for key, label in STAGES]
    for label, key in rows:
        if max(old[key] + new[key]) == 0.0:
            continue
        lines.append(f"| {label} | {spread(old[key])} | {spread(new[key])} | "
                     f"{ratio(new[key], old[key])} |")
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("old")
    parser.add_argument("new")
    parser.add_argument("logs", nargs="+")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--threads", type=int)
    parser.add_argument("--keep")
    args = parser.parse_args()
    env = dict(os.environ)
    if args.threads is not None:
        env["RAYON_NUM_THREADS"] = str(args.threads)
    binaries = [("old", os.path.abspath(args.old)), ("new", os.path.abspath(args.new))]
    threads = f"RAYON_NUM_THREADS={args.threads}" if args.threads else "both cores"
    print(f"{args.runs} alternating rounds per log, {threads}; stages: seconds summed "
          "over the run's pairs (the run summary's wall time of each stage).\n")
    with tempfile.TemporaryDirectory() as scratch:
        work = args.keep or scratch
        os.makedirs(work, exist_ok=True)
        for log in args.logs:
            results, identical = measure_log(log, binaries, args.runs, env, work)
            name = os.path.basename(log)
            print(table(name, results, identical))


if __name__ == "__main__":
    main()
