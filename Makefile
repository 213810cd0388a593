# Two commands do everything: `make demo` and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup demo test test-slow lint docs-check clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	# The CPU build of torch must come first and spelled exactly so (see README).
	$(BIN)/python -m pip install torch==2.13.0
	$(BIN)/python -m pip install -e '.[dev]'
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/grip demo --out demo_out

test: $(STAMP)
	$(BIN)/python -m pytest tests

test-slow: $(STAMP)
	$(BIN)/python -m pytest tests -m slow

docs-check: $(STAMP)
	$(BIN)/python -m pytest tests/test_readme_commands.py

lint: $(STAMP)
	$(BIN)/ruff check grip envs policies prism_tools tests

clean:
	rm -rf $(VENV) demo_out
