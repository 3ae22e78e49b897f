# make demo / make test work on a fresh machine with nothing but Python.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# The demo needs only the project itself (core, envs, baselines): no torch, RL or Ray.
DEMO_STAMP := $(VENV)/.installed-demo
DEMO_RUNS ?= 20

.PHONY: install demo test test-fast lint bench clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first and pinned, so pip never pulls a multi-GB CUDA build for the [rl] extra.
	$(PY) -m pip install --quiet "torch==2.13.0"
	$(PY) -m pip install --quiet -e ".[rl,dev,ray]"
	touch $(STAMP) $(DEMO_STAMP)

$(DEMO_STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e .
	touch $(DEMO_STAMP)

install: $(STAMP)

# The first run in a clone compiles the planners' numba kernels (about a minute or two,
# the "(compiling)" step of the progress bar and "plan_time_warmup_ms" of results.json); numba
# caches them in __pycache__, so later runs start at once.
demo: $(DEMO_STAMP)
	$(VENV)/bin/activetrack simulate --scenario paper --planner gsr --planner gbes --planner rm \
		--runs $(DEMO_RUNS) --seed 0 --out results/demo --overwrite

# The kernels are compiled once per clone (numba's cache in __pycache__). The tests marked
# `kernels` also run as plain Python (NUMBA_DISABLE_JIT=1: the kernels' source checked line
# by line), on the second core beside the main run; its output follows the main run's.
test: $(STAMP)
	@NUMBA_DISABLE_JIT=1 $(PY) -m pytest -q -p no:cacheprovider -m kernels \
		> $(VENV)/kernels-plain.log 2>&1 & plain=$$!; \
	$(PY) -m pytest -q -p no:cacheprovider; main=$$?; \
	wait $$plain; kern=$$?; \
	echo "--- NUMBA_DISABLE_JIT=1 pytest -m kernels"; cat $(VENV)/kernels-plain.log; \
	test $$main -eq 0 && test $$kern -eq 0

test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

lint: $(STAMP)
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check .

bench: $(STAMP)
	$(PY) -m pip install --quiet -e ".[bench]"
	$(PY) benchmarks/throughput.py

clean:
	rm -rf $(VENV) results .pytest_cache
