"""One local Ray cluster for the whole session (starting one costs ~4 s), the
test fleet, and the reference `looming batch` run the driver must match."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
import ray
from fleet import write_fleet

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def looming_bin() -> Path:
    """The release binary (`cargo test --release` builds it), or $LOOMING_BIN."""
    binary = Path(os.environ.get("LOOMING_BIN", REPO / "target" / "release" / "looming"))
    if not os.access(binary, os.X_OK):
        pytest.fail(f"no looming binary at {binary}: run `cargo build --release` or set LOOMING_BIN")
    return binary


@pytest.fixture(scope="session")
def ray_cluster() -> Iterator[None]:
    """A 2-CPU local cluster, offline and without the dashboard (faster to start)."""
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    ray.init(num_cpus=2, include_dashboard=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="session")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_fleet(tmp_path_factory.mktemp("fleet"))


@pytest.fixture(scope="session")
def batch_out(fleet: Path, looming_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`looming batch` on the fleet: what the driver's fleet files must equal."""
    out = tmp_path_factory.mktemp("batch") / "out"
    run = subprocess.run([looming_bin, "batch", fleet, "-o", out, "-q"], check=False)
    assert run.returncode == 1, "the garbage log fails"
    return out
