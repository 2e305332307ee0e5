"""`python -m looming_fleet.ray` on a local 2-CPU Ray cluster against `looming batch`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from looming_fleet.ray import main

FLEET_FILES = ("fleet.json", "near_misses.jsonl", "near_misses.csv")


def fleet_entries(out: Path) -> dict[str, dict[str, Any]]:
    """fleet.json's entries by file name (unique in the test fleet)."""
    return {Path(e["input"]).name: e for e in json.loads((out / "fleet.json").read_text())}


def relative_text(out: Path, name: str) -> str:
    """A fleet file with its output folder replaced, to compare runs into different folders."""
    return (out / name).read_text().replace(str(out), "OUT_DIR")


def wrapper(tmp_path: Path, real: Path, crash: str) -> tuple[Path, Path]:
    """A `looming` that notes each run on safe.mcap (and its engine threads) in a file, then runs `crash` (shell).

    Every other run (other logs, --list, --merge-only) goes straight to the real binary.
    """
    attempts = tmp_path / "attempts"
    script = tmp_path / "looming"
    script.write_text(
        "#!/bin/sh\n"
        'case " $* " in *" --only safe.mcap "*)\n'
        f"  echo \"attempt threads=$RAYON_NUM_THREADS\" >> '{attempts}'\n"
        f"  {crash}\n"
        "esac\n"
        f"exec '{real}' \"$@\"\n"
    )
    script.chmod(0o755)
    return script, attempts


@pytest.fixture(scope="session")
def ray_run(fleet: Path, looming_bin: Path, ray_cluster: None, tmp_path_factory: pytest.TempPathFactory):
    """The driver as a user runs it (`python -m`, its own process), joining the session's cluster."""
    out = tmp_path_factory.mktemp("ray") / "out"
    run = subprocess.run(
        [sys.executable, "-m", "looming_fleet.ray", fleet, "-o", out, "--address", "auto", "--looming", looming_bin],
        check=False,
        capture_output=True,
        text=True,
    )
    return out, run


@pytest.fixture
def two_logs(fleet: Path) -> list[str]:
    """A small fleet for the retry tests: cut-in.mcap and safe.mcap."""
    return [str(fleet / "day1" / "cut-in.mcap"), str(fleet / "safe.mcap")]


def test_every_log_gets_its_status(ray_run) -> None:
    out, run = ray_run
    assert run.returncode == 1, f"the garbage log fails: {run.stderr}"
    entries = fleet_entries(out)
    assert {name: e["status"] for name, e in entries.items()} == {
        "cut-in.mcap": "processed",
        "crossing.mcap": "processed",
        "safe.mcap": "processed",
        "truncated.mcap": "processed",
        "no-lidar.mcap": "skipped",
        "garbage.mcap": "failed",
    }
    assert "truncated" in entries["truncated.mcap"]["reason"]
    assert "no LiDAR topic" in entries["no-lidar.mcap"]["reason"]
    assert "not an MCAP file" in entries["garbage.mcap"]["reason"]
    assert (out / "logs" / "day1" / "cut-in.mcap").exists()
    assert "[6/6]" in run.stderr and "4 processed, 0 up to date, 1 skipped, 1 failed, 0 lost" in run.stderr


def test_same_fleet_files_as_batch(ray_run, batch_out: Path) -> None:
    out, _ = ray_run
    for name in ("near_misses.jsonl", "near_misses.csv"):
        assert relative_text(out, name) == relative_text(batch_out, name), name
    ranked = [json.loads(line) for line in (out / "near_misses.jsonl").read_text().splitlines()]
    assert [Path(n["log"]).name for n in ranked] == ["cut-in.mcap", "crossing.mcap"]
    # fleet.json too, but for each log's seconds (those of the run that did the work).
    ours, theirs = fleet_entries(out), fleet_entries(batch_out)
    for entries, folder in ((ours, out), (theirs, batch_out)):
        for entry in entries.values():
            entry.pop("seconds")
            if entry["output"]:
                entry["output"] = entry["output"].replace(str(folder), "OUT_DIR")
    assert ours == theirs


def test_a_rerun_redoes_nothing_and_writes_the_same_files(ray_run, fleet: Path, looming_bin: Path, capfd) -> None:
    out, _ = ray_run
    before = {name: (out / name).read_bytes() for name in FLEET_FILES}
    records = sorted((out / "logs").rglob("*.batch.json"))
    mtimes = [r.stat().st_mtime_ns for r in records]
    assert main([str(fleet), "-o", str(out), "--looming", str(looming_bin)]) == 1
    assert "0 processed, 6 up to date, 0 skipped, 0 failed, 0 lost" in capfd.readouterr().err
    assert [r.stat().st_mtime_ns for r in records] == mtimes
    assert {name: (out / name).read_bytes() for name in FLEET_FILES} == before


def test_a_task_killed_once_is_retried(
    ray_cluster: None, two_logs: list[str], looming_bin: Path, tmp_path: Path, capfd
) -> None:
    marker = tmp_path / "crashed"
    script, attempts = wrapper(tmp_path, looming_bin, f"[ -e '{marker}' ] || {{ touch '{marker}'; kill -9 $$; }}")
    out = tmp_path / "out"
    assert main([*two_logs, "-o", str(out), "--looming", str(script)]) == 0, capfd.readouterr().err
    assert attempts.read_text().splitlines() == ["attempt threads=1"] * 2
    assert {name: e["status"] for name, e in fleet_entries(out).items()} == {
        "cut-in.mcap": "processed",
        "safe.mcap": "processed",
    }


def test_a_task_that_always_crashes_is_reported_after_two_attempts(
    ray_cluster: None, two_logs: list[str], looming_bin: Path, tmp_path: Path, capfd
) -> None:
    script, attempts = wrapper(tmp_path, looming_bin, "echo 'out of memory' >&2; exit 137")
    out = tmp_path / "out"
    assert main([*two_logs, "-o", str(out), "--looming", str(script), "--cpus-per-task", "2"]) == 1
    assert attempts.read_text().splitlines() == ["attempt threads=2"] * 2
    err = capfd.readouterr().err
    assert "safe.mcap LOST after 2 attempts" in err, err
    assert f"  {two_logs[1]}: looming exit code 137 (128 + SIGKILL): out of memory" in err, err
    assert list(fleet_entries(out)) == ["cut-in.mcap"], "a lost log has no record"


def test_process_options_after_double_dash_reach_every_log(
    ray_cluster: None, two_logs: list[str], looming_bin: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    # The planted cut-in's time to contact is 1.0 s: no near miss below 0.1 s.
    assert main([*two_logs, "-o", str(out), "--looming", str(looming_bin), "--", "--event-ttc", "0.1"]) == 0
    assert (out / "near_misses.jsonl").read_text() == ""


def test_a_missing_binary_is_a_clear_usage_error(tmp_path: Path) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "looming_fleet.ray", tmp_path, "-o", tmp_path / "out", "--looming", tmp_path / "nope"],
        check=False,
        capture_output=True,
        text=True,
    )
    assert run.returncode == 2
    assert "no looming binary" in run.stderr and "--looming PATH" in run.stderr, run.stderr


def test_no_binary_on_path_is_a_clear_usage_error(tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.delenv("LOOMING", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    assert main([str(tmp_path), "-o", str(tmp_path / "out")]) == 2
    assert "'looming' is not an executable file or on PATH" in capsys.readouterr().err


def test_a_missing_input_is_named_with_its_error(ray_cluster: None, looming_bin: Path, tmp_path: Path, capfd) -> None:
    """A missing input is a failed log with its reason, in the merged fleet.json too (as `looming batch`)."""
    missing = tmp_path / "nope.mcap"
    out = tmp_path / "out"
    assert main([str(missing), "-o", str(out), "--looming", str(looming_bin)]) == 1
    err = capfd.readouterr().err
    assert "nope.mcap failed: No such file or directory" in err, err
    entries = json.loads((out / "fleet.json").read_text())
    assert [e["status"] for e in entries] == ["failed"]
    assert "No such file or directory" in entries[0]["reason"]
