"""Run `looming batch` over a fleet as Ray tasks, one per log, then merge.

Each task runs the `looming` binary on one log (`looming batch INPUT... -o
OUT_DIR --only RELATIVE`), so it writes exactly what `looming batch` writes
for that log: the annotated output and its record under OUT_DIR/logs, and a
log whose record still holds is not redone. The fleet files are then built on
the driver by `looming batch --merge-only OUT_DIR`, the code that writes them
after a single-machine or sharded run, so their content and ranking cannot
drift from `looming batch`. The Rust side stays the only implementation of
processing and merging; this module only schedules.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import ray

if not hasattr(ray, "init"):
    # Python put the current folder first on sys.path and it is this file's
    # folder, so `import ray` found this file instead of the ray package.
    raise ImportError("run `python -m looming_fleet.ray` from another folder than python/looming_fleet/")

USAGE_ERROR = 2
# Exit codes after which the binary has written the log's record: 1 means the
# log failed (garbage, unreadable), which is a result, not a crash.
FINISHED_CODES = (0, 1)
# Attempts per log: the first run and one retry.
ATTEMPTS = 2
# Longest wait between two looks at the finished tasks: one ray.wait per
# batch of finished tasks, not per task, keeps the loop linear in a fleet of
# thousands of logs.
PROGRESS_SECONDS = 1.0
STDERR_TAIL_CHARS = 1500


class LogTaskError(RuntimeError):
    """The binary did not finish a log (crashed, killed, no record): Ray retries the task."""


@dataclass(frozen=True)
class Log:
    """One log of the fleet, as `looming batch --list` names it."""

    relative: str
    input: str
    output: str


@dataclass(frozen=True)
class Fleet:
    """What every task of one run shares: the absolute inputs and OUT_DIR, and the options for `looming batch`."""

    inputs: list[str]
    out_dir: str
    force: bool
    process_options: list[str]

    def task_arguments(self, log: Log) -> list[str]:
        """`looming batch` arguments for one log: one log, one job, no progress output."""
        arguments = ["batch", *self.inputs, "-o", self.out_dir, "--only", log.relative, "--jobs", "1", "--quiet"]
        if self.force:
            arguments.append("--force")
        return arguments + self.process_options


@dataclass(frozen=True)
class Lost:
    """A log whose task failed on every attempt: it has no record, so the merge cannot list it."""

    log: Log
    error: str


def runtime_env(text: str) -> dict[str, Any]:
    """--runtime-env's value: a JSON object, said so in the usage error when it is not."""
    try:
        value = json.loads(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"not JSON: {error}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("not a JSON object")
    return value


def parse_args(argv: Sequence[str]) -> tuple[argparse.Namespace, list[str]]:
    """Split off the process options after `--` (passed to every task verbatim), then parse ours."""
    argv = list(argv)
    if "--" in argv:
        cut = argv.index("--")
        argv, process_options = argv[:cut], argv[cut + 1 :]
    else:
        process_options = []
    parser = argparse.ArgumentParser(
        prog="python -m looming_fleet.ray",
        description=(
            "Run `looming batch` over a fleet as Ray tasks, one per log, then build "
            "OUT_DIR's fleet files with `looming batch --merge-only`: the same outputs, "
            "records, fleet.json and near-miss ranking as `looming batch`. INPUT and "
            "OUT_DIR must be on storage every Ray worker sees at the same path."
        ),
        epilog=(
            "Options after `--` go to every log's `looming batch` run (process "
            "options: topics, --extrinsic, --event-ttc, --strict, ...). Exit codes as "
            "`looming batch`: 0 every log processed or skipped, 1 a log failed or its "
            "task failed twice, 2 usage (bad arguments, no looming binary)."
        ),
    )
    parser.add_argument(
        "inputs", nargs="+", metavar="INPUT", help="folders (every *.mcap below), MCAP files or manifests (.txt)"
    )
    parser.add_argument(
        "-o", "--output", required=True, metavar="OUT_DIR", help="output folder, as for `looming batch`"
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster to join: `auto` for the one this machine belongs to, or ray://HOST:PORT "
        "[default: start a local cluster on this machine's cores]",
    )
    parser.add_argument(
        "--looming",
        metavar="PATH",
        help="the looming binary [default: $LOOMING, else `looming` on PATH]; a bare name is "
        "looked up again on each worker (beside its Python, then on its PATH)",
    )
    parser.add_argument(
        "--cpus-per-task",
        type=int,
        default=1,
        metavar="N",
        help="Ray CPUs per log, and the engine's threads in it (RAYON_NUM_THREADS) [default: 1: "
        "one log per core is faster than fewer logs with more threads each]",
    )
    parser.add_argument(
        "--runtime-env",
        type=runtime_env,
        metavar="JSON",
        help='Ray runtime_env for the tasks, e.g. \'{"pip": ["looming-bin==0.1.0"]}\' to install the binary '
        "on the workers",
    )
    parser.add_argument("--force", action="store_true", help="redo every log, even those whose output is up to date")
    args = parser.parse_args(argv)
    if args.cpus_per_task < 1:
        parser.error("--cpus-per-task must be at least 1")
    return args, process_options


def find_binary(requested: str | None) -> tuple[str, str]:
    """The binary for the driver, and the name to send to the workers.

    A path is sent as an absolute path (workers have another cwd); a bare name
    is sent as is, so each worker finds its own install (e.g. from a pip
    runtime_env) rather than the driver's path.
    """
    name = requested or os.environ.get("LOOMING") or "looming"
    local = shutil.which(name)
    if local is None:
        raise LookupError(
            f"no looming binary: {name!r} is not an executable file or on PATH (give --looming PATH or set $LOOMING)"
        )
    for_workers = os.path.abspath(name) if os.sep in name else name
    return local, for_workers


def list_logs(binary: str, inputs: Sequence[str], out_dir: str) -> list[Log]:
    """The fleet's logs, from `looming batch --list`: the binary alone decides what a batch runs.

    Raises subprocess.CalledProcessError (its stderr already shown) on a bad
    input, with the binary's exit code.
    """
    listed = subprocess.run(
        [binary, "batch", *inputs, "-o", out_dir, "--list"],
        stdout=subprocess.PIPE,
        text=True,
        check=True,
    )
    rows = [json.loads(line) for line in listed.stdout.splitlines() if line.strip()]
    return [Log(relative=row["relative"], input=row["input"], output=row["output"]) for row in rows]


def _worker_binary(name: str) -> str:
    """Resolve the binary on the worker: a bare name is looked for beside this Python too.

    pip puts a wheel's scripts (the maturin `looming-bin` wheel's `looming`)
    beside the interpreter of the runtime_env's virtualenv, which need not be
    on PATH.
    """
    search = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")])
    found = shutil.which(name, path=search) if os.sep not in name else shutil.which(name)
    if found is None:
        raise LogTaskError(f"no looming binary {name!r} on worker {os.uname().nodename}")
    return found


def _describe_exit(code: int) -> str:
    """An exit code in words: shells report a signal as 128 + its number."""
    if code < 0:
        return f"killed by {signal.Signals(-code).name}"
    if code > 128 and code - 128 in signal.valid_signals():
        return f"exit code {code} (128 + {signal.Signals(code - 128).name})"
    return f"exit code {code}"


def _mtime_ns(path: Path) -> int | None:
    """A record's modification time, None while the log has none: tells a redone log from an up-to-date one."""
    try:
        return path.stat().st_mtime_ns
    except FileNotFoundError:
        return None


def run_log(binary: str, arguments: list[str], record: str, threads: int) -> dict[str, Any]:
    """Ray task: run `looming batch ... --only RELATIVE` on one log; return its fleet entry.

    Returns {"entry": the record's entry, "redone": whether this run wrote the
    record (False: it was up to date)}. Raises LogTaskError, which makes Ray
    run the task once more, when the binary did not finish the log: killed,
    an exit code other than 0 or 1, or no readable record.
    """
    record_path = Path(record)
    before = _mtime_ns(record_path)
    try:
        done = subprocess.run(
            [_worker_binary(binary), *arguments],
            check=False,  # the exit code is examined below
            env=dict(os.environ, RAYON_NUM_THREADS=str(threads)),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
    except OSError as error:
        raise LogTaskError(f"cannot run {binary!r} on worker {os.uname().nodename}: {error}") from None
    tail = done.stderr.strip()[-STDERR_TAIL_CHARS:]
    if done.returncode not in FINISHED_CODES:
        raise LogTaskError(f"looming {_describe_exit(done.returncode)}" + (f": {tail}" if tail else ""))
    try:
        entry = json.loads(record_path.read_text())["entry"]
    except (OSError, ValueError, KeyError) as error:
        raise LogTaskError(
            f"looming {_describe_exit(done.returncode)} but left no readable record ({error}): {tail}"
        ) from None
    return {"entry": entry, "redone": _mtime_ns(record_path) != before}


def _error_text(error: Exception) -> str:
    """The task's own exception message rather than Ray's wrapper with its traceback."""
    cause = getattr(error, "cause", None)
    return str(cause) if cause is not None else str(error).strip().splitlines()[-1]


def progress_line(done: int, total: int, log: Log, result: dict[str, Any]) -> str:
    """One line per finished log, worded as `looming batch` words its own."""
    entry = result["entry"]
    head = f"  [{done}/{total}] {log.relative}"
    if not result["redone"]:
        return f"{head} up-to-date"
    if entry["status"] == "processed":
        reason = f": {entry['reason']}" if entry.get("reason") else ""
        counts = f"{entry['scans']} scans, {entry['events']} near misses"
        return f"{head} processed ({counts}) in {entry['seconds']:.1f} s{reason}"
    return f"{head} {entry['status']}: {entry.get('reason')}"


def run_tasks(
    logs: Sequence[Log], binary: str, fleet: Fleet, args: argparse.Namespace
) -> tuple[dict[str, int], list[Lost]]:
    """Submit one task per log, report each as it finishes; the counts per outcome and the lost logs."""
    task = ray.remote(run_log).options(
        num_cpus=args.cpus_per_task,
        max_retries=ATTEMPTS - 1,
        retry_exceptions=True,
        runtime_env=args.runtime_env,
    )
    pending = {
        task.remote(
            binary,
            fleet.task_arguments(log),
            log.output + ".batch.json",
            args.cpus_per_task,
        ): log
        for log in logs
    }
    counts = {"processed": 0, "up to date": 0, "skipped": 0, "failed": 0}
    lost: list[Lost] = []
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=PROGRESS_SECONDS)
        for ref in ready:
            log = pending.pop(ref)
            done = len(logs) - len(pending)
            try:
                result = ray.get(ref)
            except ray.exceptions.RayError as error:
                lost.append(Lost(log, _error_text(error)))
                print(
                    f"  [{done}/{len(logs)}] {log.relative} LOST after {ATTEMPTS} attempts: {lost[-1].error}",
                    file=sys.stderr,
                )
                continue
            counts[result["entry"]["status"] if result["redone"] else "up to date"] += 1
            print(progress_line(done, len(logs), log, result), file=sys.stderr, flush=True)
    return counts, lost


def merge(binary: str, out_dir: str) -> int:
    """Build the fleet files from every record under OUT_DIR/logs, as `looming batch` does."""
    return subprocess.run([binary, "batch", "--merge-only", out_dir], check=False).returncode


def report_lost(lost: Sequence[Lost]) -> None:
    """Name each lost log and its last error: without a record from this run, the merge cannot list its result."""
    print(f"error: {len(lost)} logs lost: their task failed {ATTEMPTS} times, leaving no record", file=sys.stderr)
    for item in lost:
        print(f"  {item.log.input}: {item.error}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """The command; returns `looming batch`'s exit code for the same fleet (1 also for a lost log).

    Joins the Ray cluster unless the caller already has (the tests share one
    local cluster), and leaves it again only if it joined it.
    """
    args, process_options = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        local_binary, worker_binary = find_binary(args.looming)
    except LookupError as error:
        print(f"looming_fleet.ray: {error}", file=sys.stderr)
        return USAGE_ERROR
    # Absolute: a worker runs in another folder, maybe on another machine.
    inputs = [os.path.abspath(path) for path in args.inputs]
    out_dir = os.path.abspath(args.output)
    try:
        logs = list_logs(local_binary, inputs, out_dir)
    except subprocess.CalledProcessError as error:
        return error.returncode if error.returncode > 0 else 1
    joined = not ray.is_initialized()
    if joined:
        ray.init(address=args.address, include_dashboard=False)
    if __name__ != "__main__":
        # Workers then need only ray and the binary, not this package.
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    try:
        counts, lost = run_tasks(logs, worker_binary, Fleet(inputs, out_dir, args.force, process_options), args)
    finally:
        if joined:
            ray.shutdown()
    summary = ", ".join(f"{n} {what}" for what, n in counts.items())
    print(f"looming_fleet.ray: {len(logs)} logs: {summary}, {len(lost)} lost", file=sys.stderr)
    code = merge(local_binary, out_dir)
    if lost:
        report_lost(lost)
        return max(code, 1)
    return code


if __name__ == "__main__":
    sys.exit(main())
