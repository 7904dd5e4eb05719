#!/usr/bin/env bash
# Set up from nothing if needed, lint, type-check, and run every test of every package.
# Extra arguments go to pytest (e.g. -k capture, -m "not ros").
# The tests run side by side in PYTEST_WORKERS processes (pytest-xdist, default 8): they
# mostly wait on simulators, nodes and DDS, and each leases its own ROS domain and ports.
# 8 workers on a quiet 2-core machine: pytest 279-296 s on 2026-12-03, 330-336 s on the
# same machine the day after at the same CPU per test, 276-306 s on a new machine of the
# same kind that evening, bound by CPU; the long tests and the costliest classes go out
# first (gimbal_driver_testing/schedule.py; docs/testing.md, "Where the time goes").
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup_env.sh
source scripts/ros_env.sh
echo "test: ruff check"
ruff check .
echo "test: mypy"
mypy  # mypy.ini: every package under src/ (found by itself), not the tests
echo "test: pytest"
# pytest rewrites the asserts of every test module in every xdist worker, and with
# PYTHONDONTWRITEBYTECODE set (this machine's shells) it keeps no cache of the result: a
# worker's collection took 7.8 s of CPU, 2.6 s with the cache (docs/testing.md "Where the
# time goes"). So it is unset for the run, and one collection writes the cache
# (__pycache__, ignored by git) before the workers start and read it; an error there
# shows in the run itself.
unset PYTHONDONTWRITEBYTECODE
python -m pytest --collect-only -q src tests > /dev/null 2>&1 || true
python -m pytest -n "${PYTEST_WORKERS:-8}" src tests "$@"
