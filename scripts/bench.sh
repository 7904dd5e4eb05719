#!/usr/bin/env bash
# `make bench`: set up if needed, then print the benchmark JSON (bench/run.py).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup_env.sh >&2
source scripts/ros_env.sh
exec python bench/run.py "$@"
