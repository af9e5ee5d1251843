# One entry point per job; each creates (or reuses) the virtual environment in .venv.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test bench venv clean phase_vi

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/calib demo --out demo_output

# real data: the NREL Phase VI, measured sequence H (README "Real data")
phase_vi: $(STAMP)
	$(VENV)/bin/calib run workflows/phase_vi.toml --out phase_vi_output

test: $(STAMP)
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) .bench-venv demo_output bench_output phase_vi_output .calib_cache
