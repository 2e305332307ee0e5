#!/usr/bin/env bash
# Every test: the Rust tests, then the Ray driver's (python/tests, on a local
# 2-CPU Ray cluster) against the release binary the first step builds.
#
# Usage: bash scripts/test.sh
#   The Python tests run in a virtual environment, target/pyvenv, created on
#   the first run (python3 -m venv); the first run downloads ray from PyPI
#   (~300 MB installed), later runs reuse it.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --release --locked
venv=target/pyvenv
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/python" -m pip install -q -e 'python[test]'
LOOMING_BIN="$PWD/target/release/looming" "$venv/bin/python" -m pytest -q python/tests
