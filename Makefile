# The two commands a newcomer needs: `make run` and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: run test test-all bench setup ros1 ros2 postgres clean run-tables

$(BIN)/mapupdate: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	$(BIN)/python -m mapupdate.warm || echo "(kernels not compiled ahead: the first run compiles them)"
	touch $@

setup: $(BIN)/mapupdate

# ROS 1 from Debian for the live node's tests (skipped, with the reason, where it cannot be had)
ros1: setup
	@sh ros/install-ros1.sh $(BIN)/python

# ROS 2 Jazzy's wheels in .venv-ros2 for the ROS 2 node's tests (skipped, with the reason,
# where they cannot be had)
ros2: setup
	@sh ros/install-ros2.sh $(PY)

# Debian's PostgreSQL server for the map store's PostgreSQL tests, as root only (they skip,
# with the reason, where it cannot be had)
postgres:
	@if [ "$$(id -u)" = 0 ] && ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq postgresql >/dev/null 2>&1) || echo "(postgresql not installed: the PostgreSQL map store tests will skip)"; fi

run: setup
	$(BIN)/mapupdate run $(ARGS)

# two test processes (pytest-xdist), each test file in one of them: its module fixtures are
# made once
test: setup ros1 ros2 postgres
	$(BIN)/python -m pytest -q -m "not slow" -n 2 --dist loadfile $(ARGS)

test-all: setup ros1 ros2 postgres
	$(BIN)/python -m pytest -q -n 2 --dist loadfile $(ARGS)

bench: setup
	$(BIN)/python benchmarks/run.py $(ARGS)

clean:
	rm -rf $(VENV) .venv-ros2 build *.egg-info

# Run the built-in warehouse with its default seed and copy the tables into docs/main_job.md.
run-tables: setup
	$(BIN)/mapupdate run --out runs/tables --no-progress
	$(BIN)/python -m scenarios.run_tables runs/tables
