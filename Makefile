# Two commands do all set-up on a fresh machine:
#   make demo   builds skinrs and computes weights for the bundled hand (writes out/hand_weights.png)
#   make test   builds skinrs and runs every test (Rust unit tests, pytest, notebooks), as CI does
#   make quicktest  runs pytest without the tests marked slow (3-4 minutes less)
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
BLENDER_VENV ?= .venv-blender
export SKINRS_BLENDER_PYTHON := $(abspath $(BLENDER_VENV))/bin/python

# The dependencies and the `test` extra of pyproject.toml, read from there (one list).
DEPS = $(shell $(PYTHON) -c "import shlex, tomllib; p = tomllib.load(open('pyproject.toml', 'rb'))['project']; print(' '.join(map(shlex.quote, p['dependencies'] + p['optional-dependencies']['test'])))")

.PHONY: venv build demo test quicktest pytest lint typecheck bench clean fuzz

$(VENV)/.deps: pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q "maturin>=1.5,<2" $(DEPS)
	touch $@

# Blender as a Python module (skinrs[blender]; a 375 MB wheel, 1 GB installed) for the test that
# imports our .glb into Blender. bpy pins numpy < 2 and Python 3.11, so it gets its own venv; the
# test runs it in a subprocess and skips (saying why) when this step could not install it.
$(BLENDER_VENV)/.deps: pyproject.toml Makefile
	$(PYTHON) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python -m pip install -q "bpy>=4.2" \
	    || echo "bpy is not installable for $$($(PYTHON) --version): the Blender test will skip"
	touch $@

venv: $(VENV)/.deps $(BLENDER_VENV)/.deps

build: venv
	VIRTUAL_ENV=$(abspath $(VENV)) $(PY) -m maturin develop --release -q

demo: build
	$(PY) -m skinrs.demo --out out/hand_weights.png

pytest: build
	$(PY) -m pytest -q tests

test: build
	cargo test --release -q
	$(PY) -m pytest -q tests $(wildcard notebooks/*.ipynb) --nbmake

quicktest: build
	$(PY) -m pytest -q tests -m "not slow"

lint: venv
	cargo fmt --check
	cargo clippy --release -q --all-targets -- -D warnings
	$(PY) -m ruff check python tests
	$(PY) -m ruff format --check python tests
	$(PY) -m mypy

typecheck: venv
	$(PY) -m mypy

# Long property-based robustness run (>= 50,000 cases, 30 s per call); `make test` runs the
# short profile. Found examples are kept in tests/.hypothesis (committed).
fuzz: build
	SKINRS_FUZZ=long SKINRS_FUZZ_TIMEOUT=30 $(PY) -m pytest -q -s -p no:cacheprovider tests/test_fuzz.py

bench: build
	$(PY) -m skinrs.bench bbw

clean:
	rm -rf $(VENV) $(BLENDER_VENV) target out
