# Set-up and checks. Everything installs into a local virtual environment.
#   make demo          install, then run the example pipeline on built-in data
#   make demo-numbers  the demo, then its figures quoted in docs/getting-started.md
#   make test          install (NumPy 2), then lint, type-check and run the test suite
#   make test-numpy1   install with NumPy 1.26 into .venv-numpy1, run the k-medoids
#                      agreement tests (the same training points as under NumPy 2)
#   make generalise    the generalisation benchmark (docs/generalisation.md)
#   make real          the worked examples on real motor-output logs (docs/real-motors.md)
#   make bench-effects the effects-plan benchmark (docs/plan-effects-results.md)
#   make bench-intervals coverage of the effect parameters' 95 % intervals
#                      (docs/intervals-results.md)
#   make bench-horizons open-loop prediction over horizons: speed, draws, real log (docs/horizons.md)
#   make scorecard     the randomised scorecard of the whole loop (docs/scorecard.md)
#   make scorecard2    its version 2: sizes from the claim floor, planned flights
#   make informative   planned vs task-again vs random second flights (docs/informative.md)
#   make fuzz          install, then a fuzz campaign of FUZZ_CASES mutated inputs
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
VENV1  ?= .venv-numpy1

.PHONY: install demo demo-numbers test test-numpy1 lint bench bench-effects bench-intervals bench-horizons fuzz generalise real scorecard scorecard2 informative clean

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
	$(VENV1)/bin/python -m pip install -q 'numpy>=1.26,<2' -e . 'pytest>=8'
	touch $@

install: $(STAMP)

demo: $(STAMP)
	$(MAKE) -C examples demo OMAVCTL=$(abspath $(BIN))/omavctl

demo-numbers: demo
	$(BIN)/python tools/demo_numbers.py

lint: $(STAMP)
	$(BIN)/ruff check omavctl tests benchmarks tools
	$(BIN)/ruff format --check omavctl tests benchmarks tools
	$(BIN)/mypy omavctl

# both cores, one test file per worker (about 7 minutes on 2 cores; one worker: 11).
# PYTHONDONTWRITEBYTECODE unset: the omavctl processes the tests start (about 40) then
# reuse compiled modules instead of compiling omavctl's 138 files each (about 0.1 CPU s
# a start, docs/testing.md); __pycache__/ is git-ignored
# --no-loadscope-reorder: files in tests/conftest.py's order, the slowest first (pytest-xdist 3.8)
test: lint
	PYTHONDONTWRITEBYTECODE= $(BIN)/pytest -q -n 2 --dist loadfile --no-loadscope-reorder

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

# fit and evaluate the Crazyflie and Betaflight logs of ../shared/data/real from
# their motor outputs (docs/real-motors.md; about 10 minutes on 2 cores)
real: $(STAMP)
	$(MAKE) -C examples real OMAVCTL=$(abspath $(BIN))/omavctl

# plan --objective effects against the variance plan and the task flown again, with
# hidden drag and command delay (docs/plan-effects.md; about 1 minute per seed)
bench-effects: $(STAMP)
	$(BIN)/python benchmarks/bench_effects_plan.py --out docs/plan-effects-results.md

# the effects' 95 % intervals on simulated flights with known truths, against the
# white-residual least-squares ones (docs/intervals.md; about 5 minutes on 2 cores)
bench-intervals: $(STAMP)
	nice -n 10 $(BIN)/python benchmarks/intervals.py --markdown docs/intervals-results.md
# open-loop prediction over horizons (docs/horizons.md): the batched rollouts' speed on a
# 60 s log, then four hidden-effect draws, a clean one and the real px4tools log (about 30 minutes)
bench-horizons: $(STAMP)
	$(BIN)/python benchmarks/bench_horizons.py
	$(BIN)/python benchmarks/horizons_study.py --workdir build/horizons --markdown build/horizons/study.md
# the randomised scorecard of the whole loop: tune draws, then report draws, then
# the tables (docs/scorecard.md: the split, the cost; re-running resumes)
SCORECARD_DIR ?= build/scorecard
SCORECARD_JOBS ?= 2
SCORECARD_TUNE ?= 12
SCORECARD_REPORT ?= 18
scorecard: $(STAMP)
	nice -n 10 $(BIN)/python benchmarks/scorecard.py run --split tune --draws $(SCORECARD_TUNE) \
		--jobs $(SCORECARD_JOBS) --workdir $(SCORECARD_DIR)
	nice -n 10 $(BIN)/python benchmarks/scorecard.py run --split report --draws $(SCORECARD_REPORT) \
		--jobs $(SCORECARD_JOBS) --workdir $(SCORECARD_DIR)
	$(BIN)/python benchmarks/scorecard.py analyse $(SCORECARD_DIR)/tune.jsonl \
		$(SCORECARD_DIR)/report.jsonl --markdown $(SCORECARD_DIR)/tables.md
# scorecard version 2 (docs/scorecard.md): sizes as multiples of the claim floor,
# planned flights among the families, one worker process per draw; report draws
# run until SCORECARD2_ABOVE of them hide an effect at or above the claim floor
# (at most SCORECARD2_REPORT draws). SCORECARD2_SPLIT is report10 since report2-9's
# records were read to find causes (docs/scorecard.md); the scorer's
# apparent truth (benchmarks/scorecard_truth.py) re-flies each draw's fit flight
SCORECARD2_DIR ?= build/scorecard2
SCORECARD2_TUNE ?= 12
SCORECARD2_ABOVE ?= 40
SCORECARD2_REPORT ?= 100
SCORECARD2_SPLIT ?= report10
scorecard2: $(STAMP)
	nice -n 10 $(BIN)/python benchmarks/scorecard.py run --split tune2 --draws $(SCORECARD2_TUNE) \
		--jobs $(SCORECARD_JOBS) --workdir $(SCORECARD2_DIR)
	nice -n 10 $(BIN)/python benchmarks/scorecard.py run --split $(SCORECARD2_SPLIT) --draws $(SCORECARD2_REPORT) \
		--until-above $(SCORECARD2_ABOVE) --jobs $(SCORECARD_JOBS) --workdir $(SCORECARD2_DIR)
	nice -n 10 $(BIN)/python benchmarks/scorecard_truth.py $(SCORECARD2_DIR)/$(SCORECARD2_SPLIT).jsonl \
		--out $(SCORECARD2_DIR)/$(SCORECARD2_SPLIT).apparent.json
	$(BIN)/python benchmarks/scorecard.py analyse $(SCORECARD2_DIR)/$(SCORECARD2_SPLIT).jsonl \
		--apparent $(SCORECARD2_DIR)/$(SCORECARD2_SPLIT).apparent.json --markdown $(SCORECARD2_DIR)/tables.md
# the planned second flight against the task flown again, one random candidate of
# the same pool and the best flown candidate (oracle): refit, held-out error and
# closed-loop tracking (docs/informative.md). Defaults: 6 effect sets x 2 seeds, 50
# candidates, 3 further pool candidates flown: 12 draws, two at a time, their steps
# in 2 worker processes (--workers); about 2 min of CPU a draw (estimated from one
# measured draw of --candidates 30 --pool-extra 0: 82 s of CPU, 4 min wall-clock on
# 2 busy cores; docs/informative.md, "The cost of a draw").
# Draws are cached in the workdir. docs/informative.md was made with
# INFORMATIVE_ARGS='--seeds 3 --also drag:4 inertia:4 delay:4 --pool-extra 2' (5 of
# its 9 draws ran with --pool-extra 0: the page counts them).
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
