# The two commands of the README. Both create .venv when missing and install the project
# into it (again only when pyproject.toml changed), so they are idempotent.
PYTHON ?= python3.11
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OUT    ?= results

.PHONY: install test test-all run bench bench-all accuracy accuracy-baseline fuzz lint docs \
	kernels clean

$(PY):
	$(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

install: $(STAMP)

lint: install
	$(VENV)/bin/ruff check .

# The documentation site, warnings as errors (broken links and anchors fail): build/site/.
docs: install
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet

# The numba kernels compiled into the cache on every core (what the CLI and pytest's set-up
# do first when the cache lacks them).
kernels: install
	$(PY) -c 'from semistatic.kernel_cache import warm_kernel_cache; warm_kernel_cache()'

# The fast suite (pyproject's addopts leave out the slow, bench, accuracy and fuzz markers),
# one pytest-xdist worker per core (at most four), after the docs build and the kernels'
# compilation, side by side: the one runs on one core, the other on all.
test: lint
	$(MAKE) --no-print-directory -j2 docs kernels
	$(PY) -m pytest -q -n auto --maxprocesses 4

# Every test including the slow ones (closed-loop determinism of every bundled scenario,
# fleets, real logs); bench, accuracy and fuzz keep their own targets.
test-all: lint
	$(PY) -m pytest -q -m 'not bench and not accuracy and not fuzz'

run: install
	$(VENV)/bin/semistatic run sim1 --compare --out $(OUT)/sim1

# The speed goals as one table (the README's speed section); every benchmark: bench-all.
bench: install
	$(PY) -m pytest -q -s -m bench benchmarks/test_bench_goals.py

bench-all: install
	$(PY) -m pytest -q -s -m bench benchmarks

# Map accuracy, statistically: a campaign of the five paper scenarios over ten seeds
# compared with the stored baseline (exit 1 on a regression beyond the tolerances), then
# the paper's hard bounds on full five-lap runs. `make accuracy-baseline` re-records the
# baseline: only on purpose, and the commit says why.
ACCURACY_CAMPAIGN = $(VENV)/bin/semistatic campaign pal1,pal3a,pal3b,sim1,sim2 --seeds 0:9 \
	--laps 2 --jobs 2
ACCURACY_BASELINE = tests/scenarios/accuracy_baseline

accuracy: install
	rm -rf $(OUT)/accuracy
	$(ACCURACY_CAMPAIGN) --out $(OUT)/accuracy
	$(VENV)/bin/semistatic compare $(ACCURACY_BASELINE) $(OUT)/accuracy \
		--junit $(OUT)/accuracy/compare.xml --markdown $(OUT)/accuracy/compare.md
	$(PY) -m pytest -q -m accuracy tests/scenarios/test_accuracy.py

accuracy-baseline: install
	rm -rf $(OUT)/accuracy-baseline
	$(ACCURACY_CAMPAIGN) --no-figures --out $(OUT)/accuracy-baseline
	rm -rf $(ACCURACY_BASELINE)
	mkdir -p $(ACCURACY_BASELINE)
	cp $(OUT)/accuracy-baseline/manifest.json $(OUT)/accuracy-baseline/runs.parquet \
		$(OUT)/accuracy-baseline/summary.json $(ACCURACY_BASELINE)/

# Fuzzed scenario files, each accepted one run for a short lap (minutes; not in make test).
fuzz: install
	$(PY) -m pytest -q -m fuzz tests/scenarios/test_fuzz.py

clean:
	rm -rf $(VENV) $(OUT) build .pytest_cache .ruff_cache .hypothesis
