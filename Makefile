# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-lowest bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --prefer-binary -e ".[test,bench,landmarks,flow]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/facewrap demo --out out/demo

test: $(STAMP)
	$(PY) -m pytest -q

# The suite again, against the lowest numpy and scipy that pyproject.toml allows
LOWEST := .venv-lowest
test-lowest:
	$(PYTHON) -m venv $(LOWEST)
	$(LOWEST)/bin/python -m pip install --quiet --upgrade pip
	$(LOWEST)/bin/python -m pip install --quiet --prefer-binary -e ".[test,landmarks,flow]" \
		$$($(PYTHON) .ci/lowest_pins.py numpy scipy)
	$(LOWEST)/bin/python -c "import numpy, scipy; print('lowest: numpy', numpy.__version__, 'scipy', scipy.__version__)"
	$(LOWEST)/bin/python -m pytest -q

bench: $(STAMP)
	$(PY) benchmarks/run_all.py --out docs/benchmarks.md

clean:
	rm -rf $(VENV) $(LOWEST) out .pytest_cache
