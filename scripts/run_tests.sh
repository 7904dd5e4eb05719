#!/usr/bin/env bash
# Set up from nothing if needed, lint, and run every test of every package.
# Extra arguments go to pytest (e.g. -k capture, -m "not ros").
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup_env.sh
source scripts/ros_env.sh
echo "test: ruff check"
ruff check .
echo "test: pytest"
python -m pytest src tests "$@"
