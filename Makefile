# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test lint format bench clean foxglove-schemas

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/usvdrake run --out out/demo

lint: $(STAMP)
	$(BIN)/ruff format --check .
	$(BIN)/ruff check .
	$(BIN)/lint-imports

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# USVDRAKE_QUICK=1: notebooks take their short durations. TEST_JOBS pytest processes that steal
# tests from each other's queues (--dist worksteal: 9.5 min here against 10.3 min with whole
# files per process, 2026-11-27; a module fixture may then be built in both). `make test
# TEST_JOBS=0`: one process.
TEST_JOBS ?= 2
# Foxglove's published JSON schemas (npm @foxglove/schemas), one file per message, for the test
# that validates our mission logs against them; skipped quietly where npm is missing.
FOXGLOVE := $(VENV)/foxglove-schemas
export FOXGLOVE_DUMP := const s = require("@foxglove/schemas/jsonschema"), fs = require("fs"); for (const [k, v] of Object.entries(s)) fs.writeFileSync(process.argv[1] + "/" + k + ".json", JSON.stringify(v));
$(FOXGLOVE)/.done: | $(STAMP)
	@if command -v npm >/dev/null 2>&1; then \
	  npm install --prefix $(VENV)/npm --no-audit --no-fund --silent @foxglove/schemas@2.1.0 && \
	  mkdir -p $(FOXGLOVE) && \
	  (cd $(VENV)/npm && node -e "$$FOXGLOVE_DUMP" $(abspath $(FOXGLOVE))) && touch $@ || \
	  echo "could not install @foxglove/schemas: the Foxglove schema test will skip"; \
	else echo "npm not found: the Foxglove schema test will skip"; fi

foxglove-schemas: $(FOXGLOVE)/.done

test: lint foxglove-schemas
	USVDRAKE_QUICK=1 $(BIN)/python -m pytest -q -n $(TEST_JOBS) --dist worksteal --durations=15 tests --nbmake notebooks

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[bench]"
	for b in demo_speed raycast nmpc identification astar campaign; do $(BIN)/usvdrake bench $$b; done

clean:
	rm -rf $(VENV) out .pytest_cache
