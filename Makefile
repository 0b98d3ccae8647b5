# derive: two commands on a fresh machine, `make derive` and `make test`.
# Each creates .venv and installs the pinned dependencies (constraints.txt) first.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip --disable-pip-version-check -q
# pytest caches its assertion-rewritten test modules as .pyc files: with PYTHONDONTWRITEBYTECODE set
# in the caller's environment every worker rewrites every test module again (~6 s of CPU each).
unexport PYTHONDONTWRITEBYTECODE
# `make test` runs pytest in TEST_WORKERS processes (pytest-xdist): one per CPU, at most 4 (each
# holds up to ~2 GB); `make test TEST_WORKERS=0` runs the suite in one process.
TEST_WORKERS ?= $(shell n=$$(nproc 2>/dev/null || echo 1); echo $$((n < 4 ? n : 4)))

.PHONY: derive test check bench firmware-check docs clean venv venv-test

derive: $(VENV)/.core
	$(PY) -m derive generate --prune

test: $(VENV)/.test
	$(PY) -m derive generate --check --prune
	$(PY) -m pytest -q -n $(TEST_WORKERS)

bench: $(VENV)/.test
	$(PY) -m derive bench

# Cross-compile every generated C file for Cortex-M4F and M7 (needs arm-none-eabi-gcc: Debian's
# gcc-arm-none-eabi and libnewlib-arm-none-eabi) and record text and stack into firmware.json and
# the manifests; with the same toolchain a rerun changes nothing.
firmware-check: $(VENV)/.core
	$(PY) -m derive firmware-check --record

# The documentation site into site/ (MkDocs, mkdocs.yml), warnings as errors. The schema, CLI and
# generated-function pages are rendered from derive itself, and every snippet marked `run` is executed.
docs: $(VENV)/.docs
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --site-dir site

$(VENV)/.core: pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	-$(PIP) uninstall -y derive 2>/dev/null  # the distribution's name before it became derive-robotics
	$(PIP) install -c constraints.txt -e .
	touch $@

$(VENV)/.test: $(VENV)/.core
	$(PIP) install -c constraints.txt -e '.[test,pinocchio,jax,cuda,xacro,mjcf,docs,viewer]'
	touch $@

$(VENV)/.docs: $(VENV)/.core
	$(PIP) install -c constraints.txt -e '.[docs]'
	touch $@

venv: $(VENV)/.core
venv-test: $(VENV)/.test

clean:
	rm -rf $(VENV) build dist site *.egg-info
