#!/usr/bin/env bash
# The README's main command: set up from nothing if needed, then run the demo.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup_env.sh
source scripts/ros_env.sh
exec python scripts/demo.py "$@"
