# Two commands for a fresh machine with only Python 3.11: `make demo` and `make test`.
# Each creates or updates the local virtual environment .venv by itself.
PYTHON ?= python3.11
VENV := .venv
STAMP := $(VENV)/.installed-$(shell cksum pyproject.toml | cut -d' ' -f1)

.PHONY: demo test portability lint browser venv precompile clean

# pip's --no-compile: the dependencies' bytecode is written when a module is first imported,
# for the modules a run imports, instead of for every file of every package at install.
$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "$(PYTHON) not found: install Python 3.11 or run make PYTHON=/path/to/python3.11"; exit 1; }
	test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet --no-compile -e '.[dev]'
	rm -f $(VENV)/.installed-*
	touch $(STAMP)

# Optional: every shipped scenario run once (multiarm_pin/app/precompile.py), so that numba
# compiles and caches their kernels and a first run of any of them compiles nothing. Not on the
# path of demo, test or pip install: without it the kernels are compiled at first use and
# cached on disk.
precompile: $(STAMP)
	$(VENV)/bin/multiarm-pin precompile

venv: $(STAMP)

## The main job: run the default scenario, write results and a replay page.
demo: $(STAMP)
	$(VENV)/bin/multiarm-pin demo --out results/demo

# Tests of the compiled (numba) kernels, run a second time as plain Python with
# NUMBA_DISABLE_JIT=1: numpy's bounds checks then catch an out-of-range index that the
# compiled code would read silently.
KERNEL_TESTS := tests/test_kernels.py tests/test_arm_set_fast_path.py tests/test_system.py \
	tests/dynamics/test_solvers.py tests/dynamics/test_force_qp.py tests/test_closed_loop.py \
	tests/dynamics/test_unilateral.py tests/dynamics/test_impact.py tests/test_trajectories.py \
	tests/model/test_rigid_body.py tests/test_compiled_loop.py tests/test_object_pd_touching.py \
	tests/test_contact_loop_kernel.py

## The whole test suite (installs headless Chromium for the browser test when it can), on two
## worker processes (pytest-xdist, a test file per worker at a time: numba compiles each
## kernel on one core, so two processes use both), then the compiled kernels' tests again
## without compilation (bounds-checked; also on two workers). The first pass lists its 25
## slowest tests, so that a CI log shows where the suite's time goes.
test: $(STAMP) browser
	$(VENV)/bin/python -m pytest -q -n 2 --dist loadfile --durations=25
	NUMBA_DISABLE_JIT=1 $(VENV)/bin/python -m pytest -q -n 2 --dist loadfile -p no:cacheprovider $(KERNEL_TESTS)

## The round-off-sensitive tests (grasp, solvers, unilateral contacts, events) under other
## CPUs' arithmetic: numba code-generation targets, OpenBLAS kernels and numpy SIMD paths that
## this machine can execute, each in a fresh numba cache (tools/portability.py; not in `make test`).
portability: $(STAMP)
	$(VENV)/bin/python tools/portability.py

## Headless Chromium for the replay-page browser test (Debian package; needs root/apt).
browser:
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing chromium for the browser test (apt-get)"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	      || echo "chromium could not be installed: the browser test will be skipped"; \
	  else echo "chromium not found and not root: the browser test will be skipped"; fi; }

lint: $(STAMP)
	$(VENV)/bin/ruff check .

clean:
	rm -rf $(VENV) build *.egg-info
