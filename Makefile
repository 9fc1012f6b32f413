# Two entry points do all set-up on a fresh machine: `make run` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
STAMP := $(VENV)/.installed

.PHONY: install run test test-slow lint bench docs clean chromium

# torch is installed first, through the constraints file, so that no dependency can pull the
# registry's CUDA build of torch. `--no-compile`: Python compiles a module when it is first imported,
# so set-up does not compile the thousands of files of torch, ray and the rest that no run imports.
# The lab (lab/, the studies, benchmarks and record: `dospcot-lab`) installs beside the library from
# its own pyproject; the library's wheel never holds it.
$(STAMP): pyproject.toml lab/pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -q --no-compile -c constraints.txt torch
	$(PIP) install -q --no-compile -c constraints.txt -e ".[dev,docs,ray,highway,minigrid,rate]"
	$(PIP) install -q --no-compile -c constraints.txt --no-deps -e ./lab
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)  ## the main job on its embedded default: the seed paper's protocol, 10 seeds
	$(VENV)/bin/dospcot reproduce-paper

# The rating page's browser test drives Debian's Chromium (Playwright cannot download its own browser).
chromium:
	@test -x /usr/bin/chromium || (apt-get update -qq && apt-get install -y -qq chromium) \
		|| echo "chromium not installed: tests/test_rate_page.py skips its browser test outside CI"

# The output guard runs under torch's portable kernels, which every x86-64 CPU runs alike, so that its
# stored numbers are checked the same way on any machine (`pytest` alone runs it under the CPU's own
# kernels, whose numbers it also holds to the digits every kernel agrees on).
# `--dist loadscope` keeps each test module on one worker, so a module-scoped fixture (the record's
# pages rendered, a finished sweep, the quickstart's run) is built once, not once per worker.
test: $(STAMP) chromium  ## the tests not marked slow, ruff (lint and format), and the documentation site with --strict
	$(PY) -m pytest -q -n 2 --dist loadscope --ignore tests/test_output_digests.py
	ATEN_CPU_CAPABILITY=default $(PY) -m pytest -q -n 2 tests/test_output_digests.py
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

test-slow: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist loadscope -m slow

bench: $(STAMP)  ## every benchmark row, written to BENCHMARKS.md (most of an hour: the tabular row alone took 17 minutes on 2 cores)
	$(VENV)/bin/dospcot-lab bench

docs: $(STAMP)  ## the documentation site into site/ (`$(VENV)/bin/mkdocs serve` serves it while you edit)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

clean:
	rm -rf $(VENV) build site *.egg-info
