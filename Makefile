# Two commands do everything on a fresh machine: `make demo` and `make test`.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
PYTEST  := $(BIN)/pytest

.PHONY: demo test check lint warm bench reproduce zenohd clean docs base-image

## uv installs the venv: pip's resolution, with parallel downloads, in seconds rather than the
## minute or two pip takes (docs/contributing.md, "Dependencies, and why each is there"). Compiling
## the bytecode at install, as pip does: without it every process the tests start compiles its
## imports again (make test took 28 minutes of CPU against 18).
UV_VERSION := 0.13.9

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --disable-pip-version-check uv==$(UV_VERSION)
	$(BIN)/uv pip install --quiet --compile-bytecode --python $(BIN)/python --upgrade-package pip pip \
	  -e '.[dev,docs,stonesoup,cli]'
	touch $(STAMP)

## The live dual tracker over loopback Zenoh: a router per operator and the services, one episode, the scorer's summary.
demo: $(STAMP)
	$(BIN)/tltrack demo

## Test processes: one more than the cores, since the integration and system tests spend about
## 40% of their time waiting on the processes and containers they start (docs/contributing.md).
WORKERS ?= $(shell echo $$(( $$(nproc) + 1 )))

## Every test, on every core: unit, integration over real Zenoh, system (containers, the wheel,
## the browser, the golden worktree); ruff and mypy. The 25 slowest tests are listed at the end.
test: base-image $(STAMP)
	$(MAKE) --no-print-directory -j2 lint warm  # each on a core of its own: two single-threaded jobs
	$(PYTEST) -q -ra -n $(WORKERS) --dist loadgroup --durations=25

## The container tests' base image, built in the background while the venv installs (a minute of
## debootstrap off the longest chain of tests); scripts/build_image.sh waits for it. Nothing without
## a Docker Engine; its log is build/base-image.log.
base-image:
	@if docker info >/dev/null 2>&1; then mkdir -p build; \
	  nohup scripts/build_base_image.sh >build/base-image.log 2>&1 & fi

## The fast everyday subset: lint, types and the unit tier.
check: $(STAMP)
	$(MAKE) --no-print-directory -j2 lint warm  # as in make test
	$(PYTEST) -q -ra -n auto -m unit

## The documentation site, into docs/_build/html (open site/index.html, a link to it). Warnings are
## errors: a broken link, reference or tutorial fails it (tests/test_docs.py runs it in make test).
docs: $(STAMP) warm
	$(BIN)/sphinx-build -b html -W --keep-going -q docs docs/_build/html -d docs/_build/doctrees
	ln -sfn docs/_build/html site

## Compile the particle-filter kernels once, so parallel test processes load them from the cache.
warm: $(STAMP)
	$(BIN)/python -c "from tltrack.filters.warm import warm_up; warm_up()"

lint: $(STAMP)
	$(BIN)/ruff check shared services tests examples benchmarks scripts papers docs
	$(BIN)/ruff format --check shared services tests examples benchmarks scripts papers docs
	$(BIN)/mypy

## Benchmarks (not tests): filter step times and speedups.
bench: $(STAMP)
	$(BIN)/tltrack bench --json out/bench.json
	$(BIN)/tltrack bench-live --json out/bench-live.json

## The paper's figures and tables; RUNS=10000 is the paper's precision.
RUNS ?= 500
reproduce: $(STAMP)
	$(BIN)/tltrack reproduce --runs $(RUNS) --out out/reproduce

## A stock zenohd on PATH enables the zenohd interoperability test (~7.5 min to build).
zenohd:
	bash scripts/build_zenohd.sh

clean:
	rm -rf $(VENV) out build .pytest_cache .mypy_cache .ruff_cache
	rm -rf docs/_build docs/tutorials/gallery docs/reference/api site
