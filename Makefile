# Quick start: `make demo` and `make test`. Every target sets up .venv idempotently.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out/demo

.PHONY: venv demo test test-slow lint bench rl-baseline clean

$(STAMP): pyproject.toml Makefile
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# The CPU build of torch first: a bare `torch` requirement would pull a multi-GB CUDA build.
	$(PY) -m pip install -q "torch==2.13.0"
	$(PY) -m pip install -q -e ".[dev,export,tensorboard,distributed]"
	@# Headless rendering needs an EGL (or OSMesa) library; install it from Debian if missing.
	@MUJOCO_GL=egl $(PY) -c "import mujoco; mujoco.GLContext(16, 16).make_current()" 2>/dev/null || \
	  (command -v apt-get >/dev/null && (apt-get update -qq && apt-get install -y -qq libegl1 libgl1 libosmesa6 >/dev/null) || \
	   echo "warning: no EGL/OSMesa: rendering disabled")
	@touch $(STAMP)

venv: $(STAMP)

demo: venv
	$(PY) -m agents.cli demo --out $(OUT)

test: venv
	$(PY) -m pytest -m "not slow" -n 2 -q

test-slow: venv
	$(PY) -m pytest -m slow -n 2 -q

lint: venv
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

bench: venv
	$(PY) benchmarks/env_throughput.py
	$(PY) benchmarks/dynamics.py
	$(PY) benchmarks/planning.py
	$(PY) benchmarks/expert.py

# The measured residual-RL result of docs/rl.md: PPO on rough terrain (18 min budget), then the
# expert and the trained model on the rough suite.
rl-baseline: venv
	nice -n 10 $(PY) -m agents.cli train --algo ppo --terrain rough --timesteps 1000000 --time-limit-min 18 \
	  --out runs/ppo_rough --seed 0 --n-envs 2 --overwrite
	nice -n 10 $(PY) -m agents.cli evaluate --policy expert --suite rough --out runs/eval_rough_expert --workers 2 --overwrite
	nice -n 10 $(PY) -m agents.cli evaluate --policy runs/ppo_rough/model.zip --algo ppo --suite rough \
	  --out runs/eval_rough_ppo --workers 2 --overwrite

clean:
	rm -rf $(VENV) out .pytest_cache
