# Set-up and checks. Everything installs into a local virtual environment.
#   make demo          install, then run the example pipeline on built-in data
#   make test          install (NumPy 2), then lint, type-check and run the test suite
#   make test-numpy1   install with NumPy 1.26 into .venv-numpy1, run the k-medoids
#                      agreement tests (the same training points as under NumPy 2)
#   make generalise    the generalisation benchmark (docs/generalisation.md)
#   make bench-effects the effects-plan benchmark (docs/plan-effects-results.md)
#   make fuzz          install, then a fuzz campaign of FUZZ_CASES mutated inputs
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
VENV1  ?= .venv-numpy1

.PHONY: install demo test test-numpy1 lint bench bench-effects fuzz generalise clean

FUZZ_CASES ?= 3000
FUZZ_SEED ?= 1
FUZZ_STRATEGY ?= single

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q 'numpy>=2' -e '.[dev]'
	touch $@

$(VENV1)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV1)
	$(VENV1)/bin/python -m pip install -q --upgrade pip
	$(VENV1)/bin/python -m pip install -q 'numpy>=1.26,<2' -e '.[dev]'
	touch $@

install: $(STAMP)

demo: $(STAMP)
	$(MAKE) -C examples demo OMAVCTL=$(abspath $(BIN))/omavctl

lint: $(STAMP)
	$(BIN)/ruff check omavctl tests benchmarks tools
	$(BIN)/ruff format --check omavctl tests benchmarks tools
	$(BIN)/mypy omavctl

test: lint
	$(BIN)/pytest -q

fuzz: $(STAMP)
	nice -n 10 $(BIN)/python tools/fuzz_campaign.py --cases $(FUZZ_CASES) --seed $(FUZZ_SEED) \
		--strategy $(FUZZ_STRATEGY)

# fit on one flight, evaluate on another: every hidden effect, two controller
# timings, both directions, two trajectory pairs, without and with the diagnosed
# effects, the shared real log, and flights of other kinds (chirp, attitude steps:
# benchmarks/never_hurts.py) (about 6 minutes on 2 cores)
GENERALISE_LOGS ?= build/generalise
generalise: $(STAMP)
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS)
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --with-effects
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --pair check
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --pair check --with-effects
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --pair two-flights
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --pair two-flights --with-effects
	$(BIN)/python benchmarks/never_hurts.py --workdir $(GENERALISE_LOGS)/never_hurts

# plan --objective effects against the variance plan and the task flown again, with
# hidden drag and command delay (docs/plan-effects.md; about 1 minute per seed)
bench-effects: $(STAMP)
	$(BIN)/python benchmarks/bench_effects_plan.py --out docs/plan-effects-results.md

test-numpy1: $(VENV1)/.installed
	$(VENV1)/bin/pytest -q tests/test_kmedoids.py

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_simulate.py
	$(BIN)/python benchmarks/bench_read.py
	$(BIN)/python benchmarks/bench_fit.py

clean:
	rm -rf $(VENV) $(VENV1) examples/build build .pytest_cache .mypy_cache .ruff_cache
