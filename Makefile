# Quick start: `make demo` and `make test`. Every target sets up .venv idempotently.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT ?= out/demo

.PHONY: venv demo test test-slow lint bench docs strength-estimator rl-baseline rl-plan rl-scratch distilled distilled-go1 clean

$(STAMP): pyproject.toml setup.py Makefile
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# The CPU build of torch first: a bare `torch` requirement would pull a multi-GB CUDA build.
	$(PY) -m pip install -q "torch==2.13.0"
	$(PY) -m pip install -q -e ".[dev,export,tensorboard,distributed,datasets,docs,robots]"
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

comma := ,

# $(call ship,RUN,MODEL): a training run's model files into the shipped folder MODEL.
ship = mkdir -p $(2) && for f in $(MODEL_FILES); do cp $(1)/$$f $(2)/$$f; done

# $(call against_base,MODEL,TAG,BASE): MODEL and the expert it sits on (ExpertConfig JSON BASE, as in its
# rl_meta.json) on every HELD_OUT suite:seed offset (runs/eval_S_K_base_TAG, runs/eval_S_K_TAG), their paired
# comparisons (runs/compare_S_K_TAG/comparison.md) and the robust_extreme sets 100, 300 and 400 pooled
# (runs/compare_robust_extreme_pooled_TAG).
define against_base
	for run in $(HELD_OUT); do \
	  s=$${run%%:*}; seed=$${run##*:}; name=$${s}_$$seed; \
	  $(EVAL) --policy expert --expert-config '$(3)' --suite $$s --seed $$seed --out runs/eval_$${name}_base_$(2) && \
	  $(EVAL) --policy $(1)/model.zip --suite $$s --seed $$seed --out runs/eval_$${name}_$(2) && \
	  $(PY) -m agents.cli compare --baseline runs/eval_$${name}_base_$(2) --candidate runs/eval_$${name}_$(2) \
	    --out runs/compare_$${name}_$(2) || exit 1; done
	$(PY) -m agents.cli compare --baseline $(foreach k,100 300 400,runs/eval_robust_extreme_$(k)_base_$(2)) \
	  --candidate $(foreach k,100 300 400,runs/eval_robust_extreme_$(k)_$(2)) \
	  --out runs/compare_robust_extreme_pooled_$(2)
endef

# Refits the learned strength estimator of the expert's `learned` adaptation: 600 episodes of the expert in the
# extreme world on the training seeds 1000-1199, then the fit. About 15 min on 2 cores, seeded.
strength-estimator: venv
	$(PY) -m agents.cli fit-strength --seeds 1000-1199 --workers 2 --plot docs/rl_strength_estimator_fit.png

# Retrains models/ppo_residual_adaptive (models/ppo_residual_adaptive/README.md): PPO residual over the expert with
# the knee adaptation, configs/rl/ppo_residual_adaptive.yaml (75 min of training on 2 cores, seeded), then its base
# (the knee expert with cones of 0.5) and the agent on the held-out seeds of robust_extreme and robust_hard and on
# targets, with their paired comparisons (runs/compare_*_residual). About 3 h in all.
rl-baseline: venv
	$(PY) -m agents.cli train --config configs/rl/ppo_residual_adaptive.yaml --out runs/ppo_residual_adaptive --overwrite
	$(call ship,runs/ppo_residual_adaptive,models/ppo_residual_adaptive)
	$(call against_base,models/ppo_residual_adaptive,residual,{"adaptation": "knee"$(comma) "friction": 0.5})

# Trains the plan-level residual (QuadUnevenPlan-v0, configs/rl/ppo_plan.yaml: PPO over the adaptive expert's stride,
# cycle time, margin, COG height and clearance, 85 min on 2 cores, seeded) into runs/ppo_plan, then it and its base
# (the expert with the learned adaptation) on the held-out sets with their paired comparisons
# (runs/compare_*_plan). About 3 h in all.
rl-plan: venv
	$(PY) -m agents.cli train --config configs/rl/ppo_plan.yaml --out runs/ppo_plan --overwrite
	$(call against_base,runs/ppo_plan,plan,{"adaptation": "learned"})

# Retrains models/ppo_scratch (models/ppo_scratch/README.md): PPO from scratch on QuadUneven-v0 in joint_pd mode,
# configs/rl/ppo_scratch.yaml (35 min of training on 2 cores, seeded), then it and the expert on the rough suite
# with their paired comparison (runs/compare_rough_scratch). About 45 min in all.
rl-scratch: venv
	$(PY) -m agents.cli train --config configs/rl/ppo_scratch.yaml --out runs/ppo_scratch --overwrite
	$(call ship,runs/ppo_scratch,models/ppo_scratch)
	$(EVAL) --policy expert --suite rough --out runs/eval_rough_expert
	$(EVAL) --policy models/ppo_scratch/model.zip --suite rough --out runs/eval_rough_scratch
	$(PY) -m agents.cli compare --baseline runs/eval_rough_expert --candidate runs/eval_rough_scratch \
	  --out runs/compare_rough_scratch

# Retrains models/distilled (models/distilled/README.md): the expert distilled into a joint_pd network policy with a
# 0.05 m height scan on the targets suite (behaviour cloning and 6 DAgger rounds, 10.5 min with one rollout process
# on a shared core, seeded; the 22 min budget is a guard), then it on the held-out targets and smoke suites, and it
# and the expert on 3 seeds of robust_hard with their paired comparison (runs/compare_robust_hard_3_distilled).
# About 20 min in all.
DISTILL_FILES := model.zip model_obs_norm.npz rl_meta.json distill_summary.json distill_curve.png
distilled: venv
	$(PY) -m agents.cli distill --suite targets --out runs/distilled --episodes 2 --dagger-rounds 6 \
	  --beta-decay 0.7 --epochs 15 --height-scan '{"resolution": 0.05}' --workers 2 --budget-min 22 --overwrite
	mkdir -p models/distilled && for f in $(DISTILL_FILES); do cp runs/distilled/$$f models/distilled/$$f; done
	$(EVAL) --policy models/distilled/model.zip --suite targets --out runs/eval_targets_0_distilled
	$(EVAL) --policy models/distilled/model.zip --suite smoke --out runs/eval_smoke_0_distilled
	$(EVAL) --policy expert --suite robust_hard --episodes 3 --out runs/eval_robust_hard_3_expert
	$(EVAL) --policy models/distilled/model.zip --suite robust_hard --episodes 3 --out runs/eval_robust_hard_3_distilled
	$(PY) -m agents.cli compare --baseline runs/eval_robust_hard_3_expert \
	  --candidate runs/eval_robust_hard_3_distilled --out runs/compare_robust_hard_3_distilled

# Retrains models/distilled_go1 (models/distilled_go1/README.md): the same distillation on Go1 at its scale, with
# joint targets of 2 rad per unit (Go1's soft servo needs the range for the expert's knee torques), 4 episodes an
# entry and 11 DAgger rounds (about 40 min on 2 cores), then it and the expert on the held-out targets at Go1's scale.
distilled-go1: venv
	$(PY) -m agents.cli distill --suite targets --robot go1 --scale-terrain --out runs/distilled_go1 --episodes 4 \
	  --dagger-rounds 11 --beta-decay 0.8 --epochs 15 --height-scan '{"resolution": 0.05}' --pd-action-scale 2 \
	  --workers 2 --budget-min 60 --overwrite
	mkdir -p models/distilled_go1 && for f in $(DISTILL_FILES); do cp runs/distilled_go1/$$f models/distilled_go1/$$f; done
	$(EVAL) --policy models/distilled_go1/model.zip --suite targets --robot go1 --scale-terrain \
	  --out runs/eval_targets_0_distilled_go1
	$(EVAL) --policy expert --suite targets --robot go1 --scale-terrain --out runs/eval_targets_0_expert_go1

clean:
	rm -rf $(VENV) out site .pytest_cache
