# One entry point per job; each creates (or reuses) the virtual environment in .venv.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-browser test-statistics bench validate venv clean phase_vi docs

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/calib demo --out demo_output

# real data: the NREL Phase VI, measured sequence H (docs/validation/phase_vi.md)
phase_vi: $(STAMP)
	$(VENV)/bin/calib run workflows/phase_vi.toml --out phase_vi_output

# the browser the report tests drive (Debian's chromium + chromedriver); quick when present
test-browser:
	bash tests/install_browser.sh

# the tests run in PYTEST_WORKERS processes (pytest-xdist), whole files per process so that a module's
# set-up runs once; `make test PYTEST_WORKERS=auto` uses every core, `PYTEST_WORKERS=0` runs in this process
PYTEST_WORKERS ?= 2
test: $(STAMP) test-browser
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile

# the statistical suite (coverage, NEES, the diagnosis over seeds, the whole conformance matrix; CI runs
# it after `make test`)
test-statistics: $(STAMP)
	$(PY) -m pytest -q -m statistics

# speed figures, as ratios against baselines measured in the same run (a few minutes)
bench: $(STAMP)
	$(PY) benchmarks/run_all.py --suite speed

# the statistical and soak studies (coverage twins, discrepancy over seeds, Phase VI noise models,
# FMU soak): an hour or more; figures in bench_output/validation.json
validate: $(STAMP)
	$(PY) benchmarks/run_all.py --suite validate

# the documentation site (MkDocs-Material, API reference from the docstrings) into site/; warnings are errors
docs: $(STAMP)
	$(PY) -m mkdocs build --strict

clean:
	rm -rf $(VENV) .bench-venv demo_output bench_output phase_vi_output .calib_cache site
