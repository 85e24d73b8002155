# The two commands of the README:  make demo  |  make test
VENV   ?= .venv
STAMP  := $(VENV)/.installed
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl

.PHONY: demo test bench setup clean

$(STAMP): pyproject.toml requirements.lock scripts/setup.sh
	@VENV=$(VENV) bash scripts/setup.sh

setup: $(STAMP)

demo: $(STAMP)  ## the pendulum study: PID, PPO, delay, history, motorlab's fast preset
	$(VENV)/bin/motorlab run pendulum --out runs/demo-pendulum

test: $(STAMP)  ## the test suite (a few minutes on 2 cores)
	$(VENV)/bin/python -m pytest -q

bench: $(STAMP)  ## benchmarks against their peers; each prints one JSON object
	$(VENV)/bin/python benchmarks/pendulum_steps_to_success.py

clean:
	rm -rf $(VENV) runs .pytest_cache
