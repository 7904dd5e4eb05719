#!/usr/bin/env bash
# `make soak`: set up if needed, then soak every driver (scripts/soak.py) and print its JSON
# reports. SOAK_S = seconds per driver (default 40), SOAK_SEED = random seed (default 14).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup_env.sh >&2
source scripts/ros_env.sh
exec python scripts/soak.py "$@"
