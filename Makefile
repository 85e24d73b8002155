# The two commands of the README:  make demo  |  make test
VENV   ?= .venv
STAMP  := $(VENV)/.installed
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl

.PHONY: demo test test-fast test-long test-generated lint docs bench setup clean screenshots

$(STAMP): pyproject.toml requirements.lock scripts/setup.sh
	@VENV=$(VENV) bash scripts/setup.sh

# Chromium, for the tests that open HTML reports in a real browser (make test only)
$(VENV)/.browser: $(STAMP) scripts/setup.sh
	@VENV=$(VENV) bash scripts/setup.sh --browser

setup: $(STAMP)

demo: $(STAMP)  ## the pendulum study, the SAR pipeline on the MyoSuite hand and forward model + MPC on Reacher, in miniature (5.1 min from a fresh clone on 2 quiet cores, set-up from the local wheel cache included: session 24)
	$(VENV)/bin/motorlab run pendulum --out runs/demo-pendulum --resume
	$(VENV)/bin/motorlab run sar-hand-quick --out runs/demo-sar-hand-quick --resume
	$(VENV)/bin/motorlab run reacher-quick --out runs/demo-reacher-quick --resume
	@echo "Reports (open in a browser; everything is inside each file):"
	@echo "  runs/demo-pendulum/report.html"
	@echo "  runs/demo-sar-hand-quick/report.html"
	@echo "  runs/demo-reacher-quick/report.html"

# The README's pictures: the demo studies (finished steps kept), then each report's first screen in Chromium
screenshots: $(VENV)/.browser  ## docs/screenshots/*.png, the three demo reports as a reader first sees them
	$(VENV)/bin/motorlab run pendulum --out runs/demo-pendulum --resume
	$(VENV)/bin/motorlab run sar-hand-quick --out runs/demo-sar-hand-quick --resume
	$(VENV)/bin/motorlab run reacher-quick --out runs/demo-reacher-quick --resume
	$(VENV)/bin/python scripts/screenshots.py \
	  runs/demo-pendulum/report.html=docs/screenshots/pendulum.png \
	  runs/demo-sar-hand-quick/report.html=docs/screenshots/sar-hand-quick.png \
	  runs/demo-reacher-quick/report.html=docs/screenshots/reacher-quick.png

lint: $(STAMP)  ## ruff (pyflakes, isort, bugbear) and the import layers (lint-imports; see docs/design.md)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports

# Two workers, each test file on one of them (tests of one file share their fixtures and folders):
# most tests wait on `motorlab` subprocesses, so two files at a time keep both cores busy.
# tests/conftest.py adjusts loadfile: files sharing an expensive session fixture go to one worker
# together (SHARED), and files are handed out longest first (SECONDS), not most tests first.
# The tests marked `long` (tests/conftest.py LONG: end-to-end runs whose parts are tested here, benchmark
# rehearsals, learning comparisons, Ray clusters) run in make test-long; CI runs both.
# The 25 slowest tests are listed at the end: where to look when the suite grows.
# The site's strict build is a test (tests/test_docs.py), so make test does not build it a second time first.
test: lint $(VENV)/.browser  ## the test suite but the long end-to-end runs (about 11 min on 2 cores); CI adds test-long
	$(VENV)/bin/python -m pytest -q -n 2 --dist loadfile --durations=25 -m "not long"

# The documentation site (mkdocs.yml, docs/): strict, so a warning (a broken link, a docstring griffe
# cannot read) fails it; docs/reference/cli.md is generated from every command's --help as it builds
docs: $(STAMP)  ## the documentation site in site/ (open site/index.html, offline); any warning fails it
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

# (test-fast runs the cart-pole recipe end to end as the model-based workflow's test; make test leaves it to test-long)
test-fast: lint  ## the edit loop: unit tests and one end-to-end test per workflow (about 2 min on 2 cores; no browser)
	$(VENV)/bin/python -m pytest -q -m fast -n 2 --dist loadfile

# The tests marked `long` (tests/conftest.py LONG): end-to-end runs, rehearsals, Ray clusters (CI runs them after make test)
test-long: $(STAMP) $(VENV)/.browser  ## the long end-to-end tests make test leaves out (CI runs them after make test)
	$(VENV)/bin/python -m pytest -q -n 2 --dist loadfile --durations=10 -m long

# The generated tests (Hypothesis) with many more examples than make test runs: the run-folder lifecycle, every
# kind's settings, the fuzzed inputs (about 10 min on 2 cores)
test-generated: $(STAMP)  ## the generated tests at length: more run-folder lifecycles, settings values and fuzzed files
	MOTORLAB_LIFECYCLE_EXAMPLES=400 MOTORLAB_SETTINGS_EXAMPLES=100 MOTORLAB_FUZZ_EXAMPLES=200 $(VENV)/bin/python -m pytest -q \
	  tests/adversarial/test_run_folder_lifecycle.py tests/adversarial/test_settings_generated.py tests/adversarial/test_fuzz.py

bench: $(STAMP)  ## benchmarks against their peers; each prints one JSON object
	$(VENV)/bin/python benchmarks/pendulum_steps_to_success.py
	$(VENV)/bin/python benchmarks/sar_decode.py
	$(VENV)/bin/python benchmarks/sar_study.py
	$(VENV)/bin/python benchmarks/sar_study_overlap.py
	$(VENV)/bin/python benchmarks/sar_robot.py
	$(VENV)/bin/python benchmarks/dynamics_collect.py
	$(VENV)/bin/python benchmarks/dynamics_fit.py
	$(VENV)/bin/python benchmarks/mpc.py
	for env in pendulum reacher cartpole arm; do $(VENV)/bin/python benchmarks/mbrl.py $$env || exit 1; done
	$(VENV)/bin/python benchmarks/mbrl.py pusher --keep runs/bench-pusher
	$(VENV)/bin/python benchmarks/plan_latency.py
	$(VENV)/bin/python benchmarks/mpc_reward.py
	$(VENV)/bin/python benchmarks/upkie_fps.py
	$(VENV)/bin/python benchmarks/evaluate_parallel.py --repeats 3
	$(VENV)/bin/python benchmarks/tune.py --out runs/bench-tune

clean:
	rm -rf $(VENV) runs .pytest_cache
