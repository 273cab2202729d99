# bayes_fdi — two commands for a newcomer: `make demo` and `make test`.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
STAMP := $(VENV)/.installed
# Single-threaded BLAS: on 2 cores, 2-thread BLAS is several times slower on the RVM's small matrices.
export OMP_NUM_THREADS := 1
export OPENBLAS_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
export MPLBACKEND := Agg
export PYTHONHASHSEED := 0
export NO_MKDOCS_2_WARNING := 1

.PHONY: demo test lint pytest pytest-slow notebooks docs bench install clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || python3 -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q -c constraints.txt -e ".[dev,distributed]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/bayes-fdi diagnose --example --out results/example
	$(VENV)/bin/bayes-fdi reproduce --out results
	$(VENV)/bin/bayes-fdi benchmark --small --out results/benchmark-small

# Every stage runs even when an earlier one fails; `make test` fails at the end if any did and
# ends with one summary line per stage.
TEST_STAGES := lint pytest notebooks docs

test: $(STAMP)
	@failed=0; summary=""; \
	for stage in $(TEST_STAGES); do \
	  start=$$(date +%s); \
	  if $(MAKE) --no-print-directory $$stage; then result=passed; \
	  else result=FAILED; failed=$$((failed + 1)); fi; \
	  summary="$$summary$$(printf '%-10s %-6s %5d s' "$$stage" "$$result" $$(( $$(date +%s) - start )))\n"; \
	done; \
	printf '\n== make test: %d of %d stages failed ==\n%b' "$$failed" "$(words $(TEST_STAGES))" "$$summary"; \
	test "$$failed" -eq 0

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

pytest: $(STAMP)
	$(VENV)/bin/pytest -m "not slow" -n 2 --dist loadfile

pytest-slow: $(STAMP)
	$(VENV)/bin/pytest -m slow

# The notebooks run on small settings into build/notebooks (the test: any error fails it, and so
# does a machine path or numpy repr in their outputs); the docs show those executed copies
# (docs/notebooks links there), so they run once per `make test`.
NOTEBOOKS := $(wildcard notebooks/*.ipynb)
EXECUTED := $(patsubst notebooks/%,build/notebooks/%,$(NOTEBOOKS))
PACKAGE_SOURCES := $(shell find bayes_fdi -name '*.py')

notebooks: $(STAMP)
	rm -f $(EXECUTED)
	$(MAKE) --no-print-directory -j 2 $(EXECUTED)
	$(PY) notebooks/check_outputs.py $(EXECUTED)

build/notebooks/%.ipynb: notebooks/%.ipynb $(PACKAGE_SOURCES) | $(STAMP)
	@mkdir -p build/notebooks
	BAYES_FDI_SMALL=1 MPLBACKEND=module://matplotlib_inline.backend_inline \
	  $(VENV)/bin/jupyter nbconvert --to notebook --execute \
	  --ExecutePreprocessor.timeout=1800 --output-dir build/notebooks $<

docs: $(STAMP) $(EXECUTED)
	$(VENV)/bin/mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(PY) benchmarks/run.py

clean:
	rm -rf site results .pytest_cache
