# Penitentes: from ablation physics to light-in-flight videos.
# `make help` lists the targets. `make demo` and `make test` set everything up on a fresh
# Debian 12 machine (as root): Debian packages, then .venv with the package built in it.
# Stamp files under .stamps/ keep a second run fast when nothing changed.

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := help
MAKEFLAGS += --no-print-directory

PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMPS := .stamps
CONFIG ?= configs/demo.yaml
PYTEST_ARGS ?=
export PATH := $(abspath $(VENV))/bin:$(PATH)

# Debian packages: compiler and Python headers, Embree 3 for the ray engine and TBB (its scheduler,
# which the beam BVH build limits to the render's threads), LLVM 19 for Mitsuba's llvm_ad_rgb
# variant (older LLVMs crash it), OSMesa/EGL for pyvista's off-screen rendering, Chromium to check
# the HTML report, git for manifests' revisions, and clang-format to check the core's formatting.
APT_PACKAGES := build-essential git python3 python3-venv python3-dev libembree-dev libtbb-dev libllvm19 \
	libosmesa6 libegl1 libgl1 libglx-mesa0 libxrender1 chromium clang-format

CORE_SOURCES := $(shell find render/core -name '*.cpp' -o -name '*.hpp' -o -name 'CMakeLists.txt') CMakeLists.txt
PACKAGE_MARKERS := pyproject.toml $(CORE_SOURCES) $(shell find common pipeline geometry render -name '__init__.py')

CORE_FORMATTED := $(shell find render/core -name '*.cpp' -o -name '*.hpp')

.PHONY: help setup demo poster video lint docs test test-all test-cpp test-py cluster-test bench convergence sweep sanitize clean distclean validation-results

help: ## List the targets
	@grep -E '^[a-zA-Z_-]+:.*?## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*?## "}; {printf "  make %-10s %s\n", $$1, $$2}'

setup: $(STAMPS)/package ## Install Debian packages and .venv with the package built in it (idempotent)

demo: setup ## Run the whole pipeline on configs/demo.yaml (CONFIG=... for another)
	$(PY) -m pipeline run $(CONFIG)

# Assets: the previews by default (640x360, within 15 minutes on 2 cores each); FULL=1 the full configs,
# PROFILE=slurm (with FULL=1) through the cluster profile in SHARDS shards (default 8).
ASSET_SUFFIX := $(if $(FULL),,_preview)
ASSET_ARGS := $(if $(PROFILE),--shards $(or $(SHARDS),8) --profile $(PROFILE),$(if $(SHARDS),--shards $(SHARDS),))

poster: setup ## The poster (3840x2160 still + light-in-flight panel): preview by default; FULL=1, PROFILE=slurm
	$(PY) -m pipeline run configs/assets/poster$(ASSET_SUFFIX).yaml $(ASSET_ARGS)

video: setup ## The video (1920x1080, 240 frames at 24 fps): preview by default; FULL=1, PROFILE=slurm
	$(PY) -m pipeline run configs/assets/video$(ASSET_SUFFIX).yaml $(ASSET_ARGS)

lint: setup ## Lint and format checks (ruff, clang-format) and type checks (mypy); make test runs it first
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	clang-format --dry-run --Werror $(CORE_FORMATTED)
	$(VENV)/bin/mypy

# The documentation site (mkdocs.yml) in build/site; --strict fails on a broken link, anchor or include. Its log
# is shown only on failure: --quiet would hide the warnings from --strict too, and the build would pass.
docs: setup ## Build the documentation site into build/site (open build/site/index.html); make test runs it
	@log=$$(NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --site-dir build/site 2>&1) || { echo "$$log"; exit 1; }

# pytest runs in TEST_JOBS processes (pytest-xdist), one test file per process at a time, so a file's
# module fixtures are built once; tests render a fixed number of iterations, never against the clock, so a
# busy core changes how long they take and not what they measure. TEST_JOBS=0 runs them in this process.
TEST_JOBS ?= 2

test: setup ## Lint, the docs site (strict), then the C++ tests (ctest) and the Python tests (pytest), except those marked slow
	$(MAKE) lint
	$(MAKE) docs
	$(MAKE) test-cpp
	$(PY) -m pytest -m "not slow" -n $(TEST_JOBS) --dist loadfile --durations=25 --validation-report build/validation.md $(PYTEST_ARGS)

test-all: setup ## Run every test, the slow ones included
	$(MAKE) test-cpp
	$(PY) -m pytest --validation-report build/validation.md $(PYTEST_ARGS)

# make test and make test-all write the figures the tests record (tests/validation_report.py) to build/validation.md;
# this copies them to benchmarks/results/validation.md, which the docs' Validation page includes and git keeps. It
# refuses a table older than the last commit to tests/, which would describe tests that have changed since.
validation-results: ## Copy the last test run's validation table into benchmarks/results/ (docs/validation.md)
	@test -f build/validation.md || { echo "error: build/validation.md is missing: run make test (or make test-all) first" >&2; exit 1; }
	@made=$$(stat -c %Y build/validation.md); changed=$$(git log -1 --format=%ct -- tests); \
	if [ -n "$$changed" ] && [ "$$made" -lt "$$changed" ]; then \
	  echo "error: build/validation.md was written $$(date -u -d @$$made '+%F %H:%M UTC'), before the last commit to tests/" \
	    "($$(git log -1 --format=%h -- tests), $$(date -u -d @$$changed '+%F %H:%M UTC')): run make test again first" >&2; \
	  exit 1; \
	fi
	cp build/validation.md benchmarks/results/validation.md
	@echo "benchmarks/results/validation.md: $$(grep -c '^| .* | \(passed\|failed\) | ' benchmarks/results/validation.md) figures"

# A one-node SLURM cluster with accounting on localhost (as root): tests/pipeline/cluster/slurm_cluster.sh installs
# slurm-wlm, slurmdbd, munge and MariaDB, starts them, and on exit (pass or fail) stops them and purges what
# it installed, so nothing runs or starts at boot afterwards. KEEP_PACKAGES=1 keeps the packages (disabled).
CLUSTER := tests/pipeline/cluster/slurm_cluster.sh

cluster-test: setup ## Sweeps, shards and faults through a real one-node SLURM cluster (as root, under 10 min; KEEP_PACKAGES=1)
	trap '$(CLUSTER) $(if $(KEEP_PACKAGES),down,purge)' EXIT; \
	  $(CLUSTER) install && $(CLUSTER) up && $(PY) -m pytest tests/pipeline/cluster -m cluster -v -rP $(PYTEST_ARGS)

test-cpp: $(STAMPS)/venv
	cmake -S render/core -B build/ctest -G Ninja -DCMAKE_BUILD_TYPE=Release -DPTPB_BUILD_TESTS=ON > build-ctest.log 2>&1 || (cat build-ctest.log; exit 1)
	cmake --build build/ctest
	ctest --test-dir build/ctest --output-on-failure
	@rm -f build-ctest.log

# ASan + UBSan build of the core in build/sanitize: the C++ tests (which render small scenes, with
# checkpoints and resume) run as they are; the Python bindings' tests load the sanitized _core with
# the ASan runtime and libstdc++ preloaded (Python is not instrumented), leak checks off for CPython.
SANITIZE_TESTS := tests/render/ptpb/test_ptpb_hostile.py tests/render/ptpb/test_ptpb_checkpoint.py tests/render/ptpb/test_ptpb_stage.py \
	tests/render/engine/test_raytrace.py

sanitize: $(STAMPS)/venv ## Build the core with -fsanitize=address,undefined; run ctest and the bindings' tests under it
	cmake -S render/core -B build/sanitize -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPTPB_SANITIZE=ON \
	  -DPTPB_BUILD_TESTS=ON -DPTPB_BUILD_PYTHON=ON -DPython_EXECUTABLE=$(abspath $(PY)) \
	  -Dpybind11_DIR=$$($(PY) -m pybind11 --cmakedir) > build-sanitize.log 2>&1 || (cat build-sanitize.log; exit 1)
	cmake --build build/sanitize
	ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 ctest --test-dir build/sanitize --output-on-failure
	LD_PRELOAD="$$($(CXX) -print-file-name=libasan.so) $$($(CXX) -print-file-name=libstdc++.so)" \
	  ASAN_OPTIONS=detect_leaks=0 UBSAN_OPTIONS=print_stacktrace=1 \
	  $(PY) render/core/tests/sanitized_bindings.py build/sanitize $(SANITIZE_TESTS)
	@rm -f build-sanitize.log

bench: setup ## Benchmarks: ray engine, geometry against grid size, PTPB against Mitsuba and mitransient, dense rows
	$(PY) benchmarks/bench_rays.py
	@if [ -f benchmarks/bench_geometry.py ]; then $(PY) benchmarks/bench_geometry.py; fi
	$(PY) benchmarks/bench_ptpb.py
	$(PY) benchmarks/bench_dense.py

convergence: setup ## Grid convergence of the grown field: demo season on 128^2, 256^2, 512^2, seeds 1-3 (~10 min)
	$(PY) benchmarks/grid_convergence.py

sweep: setup ## Run a config sweep (default configs/sweeps/default.yaml on 2 cores; SWEEP=..., CORES=...)
	$(PY) -m pipeline sweep $(or $(SWEEP),configs/sweeps/default.yaml) --cores $(or $(CORES),2)

clean: ## Remove build folders and run outputs (keeps .venv)
	rm -rf build runs $(STAMPS)/package

distclean: clean ## Also remove .venv and every stamp
	rm -rf $(VENV) $(STAMPS)

$(STAMPS)/apt: Makefile
	@mkdir -p $(STAMPS)
	@missing=$$(for p in $(APT_PACKAGES); do \
	  [ "$$(dpkg-query -W -f='$${db:Status-Abbrev}' $$p 2>/dev/null)" = "ii " ] || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "Installing Debian packages: $$missing"; \
	  if [ "$$(id -u)" != 0 ]; then echo "error: run as root, or install these Debian packages first: $$missing" >&2; exit 1; fi; \
	  export DEBIAN_FRONTEND=noninteractive; \
	  apt-get update -qq && apt-get install -y -qq --no-install-recommends $$missing > $(STAMPS)/apt.log 2>&1 || { tail -30 $(STAMPS)/apt.log; exit 1; }; \
	fi
	@touch $@

$(STAMPS)/venv: requirements.lock $(STAMPS)/apt
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements.lock
	@touch $@

$(STAMPS)/package: $(STAMPS)/venv $(PACKAGE_MARKERS)
	$(PY) -m pip install -q --no-build-isolation --no-deps -e .
	@touch $@
