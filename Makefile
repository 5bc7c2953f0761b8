# Set-up and checks. Everything installs into a local virtual environment.
#   make demo          install, then run the example pipeline on built-in data
#   make test          install (NumPy 2), then lint, type-check and run the test suite
#   make test-numpy1   install with NumPy 1.26 into .venv-numpy1, run the k-medoids
#                      agreement tests (the same training points as under NumPy 2)
#   make generalise    the generalisation benchmark (docs/generalisation.md)
#   make bench-effects the effects-plan benchmark (docs/plan-effects-results.md)
#   make informative   planned vs task-again vs random second flights (docs/informative.md)
#   make fuzz          install, then a fuzz campaign of FUZZ_CASES mutated inputs
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
VENV1  ?= .venv-numpy1

.PHONY: install demo test test-numpy1 lint bench bench-effects fuzz generalise informative clean

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
# effects, and the shared real log (about 5 minutes on 2 cores)
GENERALISE_LOGS ?= build/generalise
generalise: $(STAMP)
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS)
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --with-effects
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --pair check
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --pair check --with-effects
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --pair two-flights
	$(BIN)/python benchmarks/generalise.py --workdir $(GENERALISE_LOGS) --pair two-flights --with-effects

# plan --objective effects against the variance plan and the task flown again, with
# hidden drag and command delay (docs/plan-effects.md; about 1 minute per seed)
bench-effects: $(STAMP)
	$(BIN)/python benchmarks/bench_effects_plan.py --out docs/plan-effects-results.md

# the planned second flight against the task flown again, one random candidate of
# the same pool and the best flown candidate (oracle): refit, held-out error and
# closed-loop tracking (docs/informative.md). Defaults: 6 effect sets x 2 seeds, 50
# candidates, 3 further pool candidates flown: 12 draws of about 12 min wall-clock
# each, two at a time (measured: 6-12 min with three at a time on 2 busy cores).
# Draws are cached in the workdir. docs/informative.md was made with
# INFORMATIVE_ARGS='--seeds 1 --also drag:2 inertia:2 delay:2 --pool-extra 2'.
INFORMATIVE_LOGS ?= build/informative
INFORMATIVE_ARGS ?=
informative: $(STAMP)
	nice -n 10 $(BIN)/python benchmarks/informative.py --workdir $(INFORMATIVE_LOGS) \
		$(INFORMATIVE_ARGS) --out docs/informative.md

test-numpy1: $(VENV1)/.installed
	$(VENV1)/bin/pytest -q tests/test_kmedoids.py

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_simulate.py
	$(BIN)/python benchmarks/bench_read.py
	$(BIN)/python benchmarks/bench_fit.py

clean:
	rm -rf $(VENV) $(VENV1) examples/build build .pytest_cache .mypy_cache .ruff_cache
