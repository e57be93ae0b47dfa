# Quick start: `make demo` and `make test`. Every target sets up .venv idempotently.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out/demo

.PHONY: venv demo test test-slow lint bench rl-baseline rl-scratch clean

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
	$(PY) benchmarks/residual_exploration.py

# The shipped residual baseline (docs/rl.md, models/ppo_residual_hard): PPO on the randomized world of the
# robust_hard suite (hard randomization, its three terrains mixed), 90 min of training on 2 cores, seeded;
# then the expert and expert + residual on robust_hard's held-out seeds (100-109) and on targets, and their
# comparisons (runs/compare_*/comparison.md). About 2 h in all.
RL_RUN := runs/ppo_residual_hard
RL_MODEL := models/ppo_residual_hard
EVAL := $(PY) -m agents.cli evaluate --workers 2 --overwrite
rl-baseline: venv
	$(PY) -m agents.cli train --config configs/rl/ppo_residual_hard.yaml --out $(RL_RUN) --overwrite
	mkdir -p $(RL_MODEL)
	for f in model.zip model_obs_norm.npz rl_meta.json train_config.json train_summary.json learning_curve.png; do \
	  cp $(RL_RUN)/$$f $(RL_MODEL)/$$f; done
	$(EVAL) --policy expert --suite robust_hard --seed 100 --out runs/eval_robust_hard_expert
	$(EVAL) --policy $(RL_MODEL)/model.zip --suite robust_hard --seed 100 --out runs/eval_robust_hard_residual
	$(PY) -m agents.cli compare --baseline runs/eval_robust_hard_expert --candidate runs/eval_robust_hard_residual \
	  --out runs/compare_robust_hard
	$(EVAL) --policy expert --suite targets --out runs/eval_targets_expert
	$(EVAL) --policy $(RL_MODEL)/model.zip --suite targets --out runs/eval_targets_residual
	$(PY) -m agents.cli compare --baseline runs/eval_targets_expert --candidate runs/eval_targets_residual \
	  --out runs/compare_targets

# The from-scratch PPO reference (docs/rl.md), about 40 min on 2 cores.
rl-scratch: venv
	$(PY) -m agents.cli train --config configs/rl/ppo_scratch.yaml --out runs/ppo_scratch --overwrite --time-limit-min 35
	mkdir -p models/ppo_scratch
	for f in model.zip model_obs_norm.npz rl_meta.json train_config.json train_summary.json learning_curve.png; do \
	  cp runs/ppo_scratch/$$f models/ppo_scratch/$$f; done
	$(EVAL) --policy models/ppo_scratch/model.zip --suite rough --out runs/eval_scratch_rough

clean:
	rm -rf $(VENV) out .pytest_cache
