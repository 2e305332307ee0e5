"""The test fleet of `tests/batch.rs`, written from Python: two planted near
misses, a safe drive, a truncated log, a log without LiDAR and random bytes."""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

SAMPLE_LOGS = Path(__file__).resolve().parents[2] / "sample_logs"
MCAP_MAGIC = b"\x89MCAP0\r\n"


def _string(text: str) -> bytes:
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def imu_only_log() -> bytes:
    """A minimal unindexed MCAP with one IMU channel and no LiDAR.

    Hand-written (header, schema, channel, ten messages, data end, footer)
    rather than with the `mcap` package: one dependency less for the test.
    """
    records = [
        _record(0x01, _string("ros2") + _string("looming_fleet tests")),
        _record(
            0x03, struct.pack("<H", 1) + _string("sensor_msgs/msg/Imu") + _string("ros2msg") + struct.pack("<I", 0)
        ),
        _record(0x04, struct.pack("<HH", 1, 1) + _string("/imu/data") + _string("cdr") + struct.pack("<I", 0)),
    ]
    for i in range(10):
        stamp = 1_000 + i * 10_000_000
        records.append(_record(0x05, struct.pack("<HIQQ", 1, i, stamp, stamp) + bytes(8)))
    records.append(_record(0x0F, struct.pack("<I", 0)))
    records.append(_record(0x02, struct.pack("<QQI", 0, 0, 0)))
    return MCAP_MAGIC + b"".join(records) + MCAP_MAGIC


def garbage() -> bytes:
    """The same 50,000 pseudo-random bytes as tests/batch.rs."""
    return bytes(((i * 2_654_435_761) % 2**32 >> 13) & 0xFF for i in range(50_000))


def write_fleet(root: Path) -> Path:
    """`day1/cut-in.mcap`, `day1/crossing.mcap`, `safe.mcap`, `truncated.mcap`,
    `no-lidar.mcap`, `garbage.mcap` below root/in; returns that folder."""
    fleet = root / "in"
    (fleet / "day1").mkdir(parents=True)
    for name in ("cut-in.mcap", "crossing.mcap"):
        shutil.copy(SAMPLE_LOGS / name, fleet / "day1" / name)
    safe = (SAMPLE_LOGS / "straight-road.mcap").read_bytes()
    (fleet / "safe.mcap").write_bytes(safe)
    (fleet / "truncated.mcap").write_bytes(safe[: len(safe) * 2 // 3])
    (fleet / "no-lidar.mcap").write_bytes(imu_only_log())
    (fleet / "garbage.mcap").write_bytes(garbage())
    return fleet
