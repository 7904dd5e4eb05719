# Thin wrappers around scripts/: each target sets up what it needs from nothing.
# Every ROS process started here runs with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST

.PHONY: setup build test test-one-core lint demo bench soak clean

setup:
	scripts/setup_env.sh --no-build

build:
	scripts/setup_env.sh

test:
	scripts/run_tests.sh

# The same run with every process pinned to CPU 0 (docs/testing.md, "On one core"): no
# verdict may depend on the machine's speed. 4 workers: CI's load per core (8 on 2 cores).
test-one-core:
	PYTEST_WORKERS=$${PYTEST_WORKERS:-4} taskset -c 0 scripts/run_tests.sh

lint: setup
	.venv/bin/ruff check .
	.venv/bin/mypy

demo:
	scripts/demo.sh

bench:
	scripts/bench.sh

# SOAK_S: seconds per driver (default 40, so about 5 min for all five); SOAK_SEED: seed.
soak:
	scripts/soak.sh

clean:
	rm -rf build install log
