# Quick start: `make demo` and `make test`. Every target sets up .venv idempotently.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out/demo

.PHONY: venv demo test test-slow lint bench docs strength-estimator learned-adaptation rl-baseline rl-sac rl-sac-continued rl-sac-features rl-sac-warmup rl-scratch clean

$(STAMP): pyproject.toml setup.py Makefile
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# The CPU build of torch first: a bare `torch` requirement would pull a multi-GB CUDA build.
	$(PY) -m pip install -q "torch==2.13.0"
	$(PY) -m pip install -q -e ".[dev,export,tensorboard,distributed,docs]"
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

# The user guide (docs/, mkdocs.yml) as a static site in site/; a broken link or page fails the build.
docs: venv
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site

bench: venv
	$(PY) benchmarks/env_throughput.py
	$(PY) benchmarks/dynamics.py
	$(PY) benchmarks/planning.py
	$(PY) benchmarks/expert.py
	$(PY) benchmarks/residual_exploration.py

MODEL_FILES := model.zip model_obs_norm.npz rl_meta.json train_config.json train_summary.json learning_curve.png
HELD_OUT := robust_extreme:100 robust_extreme:300 robust_extreme:400 robust_extreme:500 robust_extreme:600 \
  robust_hard:100 targets:0
EVAL := $(PY) -m agents.cli evaluate --workers 2 --overwrite

# $(call ship,RUN,MODEL): a training run's model files into the shipped folder MODEL.
ship = mkdir -p $(2) && for f in $(MODEL_FILES); do cp $(1)/$$f $(2)/$$f; done

# $(call against_expert,MODEL,TAG,REUSE): the expert and MODEL on every HELD_OUT suite:seed offset
# (runs/eval_S_K_expert, runs/eval_S_K_TAG), their paired comparisons (runs/compare_S_K_TAG/comparison.md) and the
# first three robust_extreme sets pooled (runs/compare_robust_extreme_pooled_TAG; the fourth and fifth, 500-519 and
# 600-619, are compared on their own); REUSE=reuse keeps expert runs found.
define against_expert
	for run in $(HELD_OUT); do \
	  s=$${run%%:*}; seed=$${run##*:}; name=$${s}_$$seed; \
	  { test "$(3)" = reuse && test -f runs/eval_$${name}_expert/results.json; } || \
	    $(EVAL) --policy expert --suite $$s --seed $$seed --out runs/eval_$${name}_expert || exit 1; \
	  $(EVAL) --policy $(1)/model.zip --suite $$s --seed $$seed --out runs/eval_$${name}_$(2) && \
	  $(PY) -m agents.cli compare --baseline runs/eval_$${name}_expert --candidate runs/eval_$${name}_$(2) \
	    --out runs/compare_$${name}_$(2) || exit 1; done
	$(PY) -m agents.cli compare --baseline $(foreach k,100 300 400,runs/eval_robust_extreme_$(k)_expert) \
	  --candidate $(foreach k,100 300 400,runs/eval_robust_extreme_$(k)_$(2)) \
	  --out runs/compare_robust_extreme_pooled_$(2)
endef

# The learned strength estimator (agents/control/adaptation/data/strength_estimator.npz, the expert's adaptation: learned; docs/rl.md,
# session 20): 600 episodes of the expert in the extreme world on training seeds 1000-1199, then the fit; about
# 15 min on 2 cores, seeded.
strength-estimator: venv
	$(PY) -m agents.cli fit-strength --seeds 1000-1199 --workers 2 --plot docs/rl_strength_estimator_fit.png

# The residual agent over the learned adaptation (models/learned_adaptation; docs/rl.md, session 20): the strength
# estimator above, then run 7's config with the expert's adaptation: learned stopped before its first update (its PPO
# residual is zero: what it adds to the expert is the estimator's gains), then the expert and it on every HELD_OUT
# set with their paired comparisons (runs/compare_*_learned). About 1 h 45 min on 2 cores.
learned-adaptation: strength-estimator
	$(PY) -m agents.cli train --config configs/rl/ppo_residual_adaptive.yaml --expert-config '{"adaptation": "learned"}' \
	  --out runs/ppo_residual_learned_prior --time-limit-min 0.0001 --overwrite
	$(call ship,runs/ppo_residual_learned_prior,models/learned_adaptation)
	$(call against_expert,models/learned_adaptation,learned)

# The shipped residual baseline (docs/rl.md, models/ppo_residual_adaptive, run 7): PPO on the extreme world (motors
# down to half their torque, payloads to +50 %, the rest of robust_hard's randomization) over a mix of six
# terrains, on top of the expert with adaptive knee gains (agents/control/adaptation/knee.py), the residual a gain on
# the stance legs' torques; 75 min of training on 2 cores, seeded; then the expert and expert + residual on the
# held-out seeds of robust_extreme (100-119, 300-319, 400-419, 500-519 and 600-619) and robust_hard (100-109), and on
# targets, with their paired comparisons (runs/compare_*_residual; runs/compare_robust_extreme_pooled_residual pools
# the first three robust_extreme sets). About 3 h in all.
rl-baseline: venv
	$(PY) -m agents.cli train --config configs/rl/ppo_residual_adaptive.yaml --out runs/ppo_residual_adaptive --overwrite
	$(call ship,runs/ppo_residual_adaptive,models/ppo_residual_adaptive)
	$(call against_expert,models/ppo_residual_adaptive,residual)

# Run 8 (docs/rl.md, models/sac_residual_adaptive): SAC in run 7's setup and budget, for comparison; then the
# same evaluations (the expert's runs are rl-baseline's when present). About 2 h 10 min on 2 cores.
rl-sac: venv
	$(PY) -m agents.cli train --config configs/rl/sac_residual_adaptive.yaml --out runs/sac_residual_adaptive --overwrite
	$(call ship,runs/sac_residual_adaptive,models/sac_residual_adaptive)
	$(call against_expert,models/sac_residual_adaptive,sac,reuse)

# Run 9 (docs/rl.md, models/sac_residual_adaptive_continued): run 8 trained for a second 75-min budget, a warm start
# from models/sac_residual_adaptive (make rl-sac first to reproduce it from scratch); then the same evaluations.
# About 2 h 10 min on 2 cores.
rl-sac-continued: venv
	$(PY) -m agents.cli train --config configs/rl/sac_residual_adaptive_continued.yaml \
	  --out runs/sac_residual_adaptive_continued --overwrite
	$(call ship,runs/sac_residual_adaptive_continued,models/sac_residual_adaptive_continued)
	$(call against_expert,models/sac_residual_adaptive_continued,sac9,reuse)

# $(call train_select,CONFIG,RUN,MODEL,TAG): train CONFIG into RUN, choose its snapshot on the validation seeds
# 200-219 of robust_extreme (quad-uneven select: every 50k steps' checkpoint and the final model, 60 episodes each,
# the expert's beside them), ship the chosen one with its selection files to MODEL, then the held-out evaluations.
define train_select
	$(PY) -m agents.cli train --config $(1) --out $(2) --overwrite
	test -f runs/eval_robust_extreme_200_expert/results.json || \
	  $(EVAL) --policy expert --suite robust_extreme --seed 200 --out runs/eval_robust_extreme_200_expert
	$(PY) -m agents.cli select --run $(2) --suite robust_extreme --seed 200 --workers 2 --overwrite \
	  --reference runs/eval_robust_extreme_200_expert
	$(call ship,$(2)/selection/selected,$(3))
	cp $(2)/selection/selection.json $(2)/selection/selection.md $(2)/selection/selection.png $(3)/
	$(call against_expert,$(3),$(4),reuse)
endef

# Run 10 (docs/rl.md, models/sac_residual_adaptive_features): run 8 with the adapted knee gains in the observation,
# from scratch, its snapshot chosen on the validation seeds; then the same evaluations. About 3 h on 2 cores.
rl-sac-features: venv
	$(call train_select,configs/rl/sac_residual_adaptive_features.yaml,runs/sac_residual_adaptive_features,models/sac_residual_adaptive_features,sac10)

# Run 11 (docs/rl.md, models/sac_residual_adaptive_warmup): run 10 with only the critics learning for the first 50k
# steps (actor_warmup_steps) and an exploration std of 0.1 at the start (initial_std), chosen and evaluated as run 10.
# About 3 h on 2 cores.
rl-sac-warmup: venv
	$(call train_select,configs/rl/sac_residual_adaptive_warmup.yaml,runs/sac_residual_adaptive_warmup,models/sac_residual_adaptive_warmup,sac11)

# The from-scratch PPO reference (docs/rl.md), about 40 min on 2 cores.
rl-scratch: venv
	$(PY) -m agents.cli train --config configs/rl/ppo_scratch.yaml --out runs/ppo_scratch --overwrite --time-limit-min 35
	$(call ship,runs/ppo_scratch,models/ppo_scratch)
	$(EVAL) --policy models/ppo_scratch/model.zip --suite rough --out runs/eval_scratch_rough

clean:
	rm -rf $(VENV) out site .pytest_cache
