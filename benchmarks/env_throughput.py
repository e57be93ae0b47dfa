"""Env throughput of QuadUneven-v0 against raw mj_step and Gymnasium's Ant-v5, in one run.

Three protocols, each printing ratios measured in the same run:

1. **Overhead** (zero action / standing): env steps/s, mj_step/s and the overhead ratio
   env_step_time / (frame_skip x mj_step_time) for both environments (resets excluded).
2. **Random actions** (``--random-steps``): uniform random actions from the action space
   (QuadUneven-v0 in torque mode on rough terrain, i.e. uniform torques over the full motor range;
   Ant-v5 as registered), resets included in the timing, per env step and per physics step.
   Averaged over ``--random-seeds`` seeds (the two envs alternate seed by seed, so machine load
   hits both alike), with the share of the time spent in ``reset``. ``--ablation`` adds the same rows
   for earlier contact models and for the current one with one change undone at a time
   (:data:`CONTACT_VARIANTS`, applied to the compiled model at run time).
3. **SB3 PPO training** (``--ppo-steps``, 0 to skip): ``PPO.learn`` wall time for QuadUneven-v0,
   QuadUnevenResidual-v0 and Ant-v5 with the same PPO settings (2 envs in a DummyVecEnv, the
   hyperparameters of configs/rl/ppo_residual.yaml, torch on 1 thread), env steps/s; the residual env twice, with
   SB3's default exploration std (1) and with the training config's (0.08). Kernels are compiled before timing.

Usage: ``python benchmarks/env_throughput.py [--steps N] [--random-steps N] [--random-seeds K] [--ppo-steps N]
[--ablation]``.
No assertions: the figures and the targets are in docs/results.md.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import mujoco
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from quad_uneven_env import constants as C

RANDOM_SEED = 0


def _contact_model(
    env: gym.Env, foot_tc: float, limb_tc: float, limb_priority: int, native_ccd: bool, sparse: bool
) -> None:
    """Set the contact stiffness (s), the limbs' priority, the convex collider and the Jacobian layout (in place)."""
    m = env.unwrapped.model
    m.opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    limbs = _limb_geoms(m)
    m.geom_solref[:, 0] = foot_tc
    m.geom_solref[:, 1] = 1.0
    m.geom_solref[limbs, 0] = limb_tc
    m.geom_priority[:] = 0
    m.geom_priority[limbs] = limb_priority
    if native_ccd:
        m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
    else:
        m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
    m.opt.jacobian = mujoco.mjtJacobian.mjJAC_SPARSE if sparse else mujoco.mjtJacobian.mjJAC_DENSE


def _limb_geoms(m: mujoco.MjModel) -> np.ndarray:
    """(ngeom,) bool: the trunk, thigh and shank geoms."""
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, i) or "" for i in range(m.ngeom)]
    return np.array([n == C.TRUNK_GEOM or n.endswith(("_thigh_geom", "_shank_geom")) for n in names])


CONTACT_VARIANTS: dict[str, Callable[[gym.Env], None]] = {
    "pre-13 (20 ms, native CCD, dense)": lambda env: _contact_model(env, 0.02, 0.02, 0, True, False),
    "7.5 ms everywhere, native CCD, dense": lambda env: _contact_model(env, 0.0075, 0.0075, 0, True, False),
    "current with native CCD": lambda env: _contact_model(env, 0.0075, 0.004, 1, True, True),
    "current with 7.5 ms limbs": lambda env: _contact_model(env, 0.0075, 0.0075, 0, False, True),
    "current with a dense Jacobian": lambda env: _contact_model(env, 0.0075, 0.004, 1, False, False),
}
"""Earlier contact models, and the current one with one change undone, as run-time edits of the compiled model."""


def measure(env_id: str, steps: int, **kwargs) -> dict[str, float]:
    """Time ``steps`` env steps with zero action, then replay the identical physics with raw mj_step.

    Each episode segment starts from a saved MuJoCo state (controls included) and is replayed
    in a separate MjData with ``frame_skip`` x ``mj_step`` per env step, so both timings cover
    exactly the same trajectory, contacts included. Resets are excluded from both.
    """
    env = gym.make(env_id, **kwargs)
    u = env.unwrapped
    zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(u.model, spec))
    replay = mujoco.MjData(u.model)
    t_env = t_mj = 0.0
    done = 0
    env.reset(seed=0)
    for _ in range(20):  # warm-up: compiled kernels are built on first use
        env.step(zero)
    env.reset(seed=0)
    while done < steps:
        mujoco.mj_getState(u.model, u.data, state, spec)
        n, ended = 0, False
        t0 = time.perf_counter()
        while done + n < steps and not ended:
            _, _, terminated, truncated, _ = env.step(zero)
            n += 1
            ended = terminated or truncated
        t_env += time.perf_counter() - t0
        mujoco.mj_setState(u.model, replay, state, spec)
        mujoco.mj_forward(u.model, replay)
        t0 = time.perf_counter()
        for _ in range(n * u.frame_skip):
            mujoco.mj_step(u.model, replay)
        t_mj += time.perf_counter() - t0
        done += n
        if ended:
            env.reset()
    env.close()
    per_env, per_mj = t_env / steps, t_mj / (steps * u.frame_skip)
    return {
        "env_steps_per_s": 1.0 / per_env,
        "mj_steps_per_s": 1.0 / per_mj,
        "frame_skip": u.frame_skip,
        "ratio": per_env / (u.frame_skip * per_mj),
    }


def measure_random(
    env_id: str, steps: int, seed: int = RANDOM_SEED, setup: Callable[[gym.Env], None] | None = None, **kwargs
) -> dict[str, float]:
    """Uniform random actions for ``steps`` env steps, resets included in the timing.

    The actions are drawn (seeded) before the clock starts; an ended episode is reset inside
    the timed loop, as an RL rollout does. Also counts the contacts after each env step and the
    episodes.

    :param setup: called with the env after ``gym.make`` (e.g. one of :data:`CONTACT_VARIANTS`).
    :return: env steps/s, physics steps/s (env steps x frame_skip / wall), mean contacts, episodes, wall (s)
        and the part of it spent in ``reset`` (s).
    """
    env = gym.make(env_id, **kwargs)
    u = env.unwrapped
    if setup is not None:
        setup(env)
    env.action_space.seed(seed)
    env.reset(seed=seed)
    for _ in range(20):  # warm-up (compiled kernels)
        env.step(env.action_space.sample())
    env.reset(seed=seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    data = u.data
    ncon = 0
    episodes = 1
    t_reset = 0.0
    t0 = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        ncon += data.ncon
        if terminated or truncated:
            t1 = time.perf_counter()
            env.reset()
            t_reset += time.perf_counter() - t1
            episodes += 1
    wall = time.perf_counter() - t0
    env.close()
    return {
        "env_steps_per_s": steps / wall,
        "physics_steps_per_s": steps * u.frame_skip / wall,
        "frame_skip": u.frame_skip,
        "contacts": ncon / steps,
        "episodes": episodes,
        "wall": wall,
        "reset_wall": t_reset,
    }


def measure_random_seeds(
    rows: dict[str, tuple[str, Callable[[gym.Env], None] | None, dict]], steps: int, seeds: int
) -> dict[str, dict[str, float]]:
    """:func:`measure_random` for every row over seeds 0..seeds-1, the rows alternating seed by seed.

    :param rows: name -> (env id, setup or None, make kwargs).
    :return: name -> totals over the seeds (rates from the summed wall time, contacts per step averaged).
    """
    runs: dict[str, list[dict[str, float]]] = {name: [] for name in rows}
    for seed in range(seeds):
        for name, (env_id, setup, kwargs) in rows.items():
            runs[name].append(measure_random(env_id, steps, seed=seed, setup=setup, **kwargs))
    out = {}
    for name, rs in runs.items():
        wall = sum(r["wall"] for r in rs)
        n = steps * len(rs)
        out[name] = {
            "env_steps_per_s": n / wall,
            "physics_steps_per_s": n * rs[0]["frame_skip"] / wall,
            "contacts": sum(r["contacts"] for r in rs) / len(rs),
            "episodes": sum(r["episodes"] for r in rs),
            "reset_share": sum(r["reset_wall"] for r in rs) / wall,
        }
    return out


def measure_ppo(
    env_id: str, steps: int, seed: int = RANDOM_SEED, log_std_init: float = 0.0, **kwargs
) -> dict[str, float]:
    """Wall time of SB3 ``PPO.learn(steps)`` on 2 envs (DummyVecEnv), env steps/s (updates included).
    ``log_std_init``: the policy's initial log exploration std (SB3's default 0, std 1)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    if env_id.startswith("QuadUnevenResidual"):
        import agents.rl  # noqa: F401  (registers QuadUnevenResidual-v0)
    torch.set_num_threads(1)
    venv = make_vec_env(env_id, n_envs=2, seed=seed, env_kwargs=kwargs)
    # Warm-up outside the timing: the env's (and the residual env's expert's) numba kernels compile on first
    # use, several seconds that would otherwise count as a third of a short run's wall time.
    venv.seed(seed + 1)
    venv.reset()
    for _ in range(20):
        venv.step(np.stack([venv.action_space.sample() for _ in range(venv.num_envs)]))
    # configs/rl/ppo_residual.yaml's hyperparameters, n_steps shortened so a short run holds 2 updates.
    n_steps = max(64, steps // 4)
    model = PPO(
        "MlpPolicy",
        venv,
        learning_rate=5e-5,
        n_steps=n_steps,
        batch_size=min(256, 2 * n_steps),
        n_epochs=5,
        target_kl=0.02,
        gamma=0.99,
        gae_lambda=0.95,
        clip_range=0.2,
        max_grad_norm=0.5,
        policy_kwargs={"net_arch": [128, 128], "log_std_init": log_std_init},
        seed=seed,
        device="cpu",
        verbose=0,
    )
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    wall = time.perf_counter() - t0
    done = int(model.num_timesteps)
    venv.close()
    return {"env_steps_per_s": done / wall, "steps": done}


def main(argv: list[str] | None = None) -> None:
    """Run the benchmarks and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="env steps per overhead measurement (0: skip)")
    parser.add_argument("--random-steps", type=int, default=3000, help="env steps of random actions (0: skip)")
    parser.add_argument("--ppo-steps", type=int, default=4096, help="PPO env steps per env (0: skip)")
    parser.add_argument("--random-seeds", type=int, default=3, help="seeds of the random-action protocol")
    parser.add_argument(
        "--ablation", action="store_true", help="also measure earlier contact models and each change undone"
    )
    args = parser.parse_args(argv)

    if args.steps > 0:
        rows = {
            "QuadUneven-v0 (rough, torque, zero action)": measure("QuadUneven-v0", args.steps, terrain="rough"),
            "QuadUneven-v0 (rough, joint_pd, standing)": measure(
                "QuadUneven-v0", args.steps, terrain="rough", action_mode="joint_pd"
            ),
            "QuadUneven-v0 (rough, torque, zero, mild)": measure(
                "QuadUneven-v0", args.steps, terrain="rough", randomization="mild"
            ),
            "QuadUneven-v0 (rough, joint_pd, standing, mild)": measure(
                "QuadUneven-v0", args.steps, terrain="rough", action_mode="joint_pd", randomization="mild"
            ),
            "Ant-v5 (Gymnasium reference)": measure("Ant-v5", args.steps),
        }
        print(f"{'env':46s} {'env steps/s':>12s} {'mj_step/s':>12s} {'frame_skip':>10s} {'overhead ratio':>15s}")
        for name, r in rows.items():
            print(
                f"{name:46s} {r['env_steps_per_s']:12.0f} {r['mj_steps_per_s']:12.0f} "
                f"{r['frame_skip']:10d} {r['ratio']:15.2f}"
            )
        print(
            "overhead ratio = env_step_time / (frame_skip x mj_step_time); target for QuadUneven-v0 <= 1.25, "
            "<= 1.3 with randomization (mild: latency, pushes and observation noise on; the replay runs on the "
            "same randomized model)\n"
        )

    if args.random_steps > 0:
        spec: dict[str, tuple[str, Callable[[gym.Env], None] | None, dict]] = {}
        if args.ablation:
            for name, setup in CONTACT_VARIANTS.items():
                spec[f"QuadUneven-v0, {name}"] = ("QuadUneven-v0", setup, {"terrain": "rough"})
        spec["QuadUneven-v0 (rough, torque)"] = ("QuadUneven-v0", None, {"terrain": "rough"})
        spec["Ant-v5"] = ("Ant-v5", None, {})
        rows = measure_random_seeds(spec, args.random_steps, args.random_seeds)
        ant = rows["Ant-v5"]
        print(f"random actions, resets included, {args.random_steps} env steps x {args.random_seeds} seeds each")
        print(
            f"{'env':58s} {'env steps/s':>12s} {'physics/s':>10s} {'x Ant env':>9s} {'x Ant phys':>10s} "
            f"{'contacts':>8s} {'episodes':>8s} {'in reset':>8s}"
        )
        for name, r in rows.items():
            print(
                f"{name:58s} {r['env_steps_per_s']:12.0f} {r['physics_steps_per_s']:10.0f} "
                f"{r['env_steps_per_s'] / ant['env_steps_per_s']:9.2f} "
                f"{r['physics_steps_per_s'] / ant['physics_steps_per_s']:10.2f} {r['contacts']:8.1f} "
                f"{r['episodes']:8d} {r['reset_share']:8.0%}"
            )
        print("targets for QuadUneven-v0: >= 1000 env steps/s and >= 0.5 x Ant-v5's physics steps/s\n")

    if args.ppo_steps > 0:
        rows = {
            "QuadUneven-v0 (rough)": measure_ppo("QuadUneven-v0", args.ppo_steps, terrain="rough"),
            "QuadUnevenResidual-v0 (rough, std 1)": measure_ppo(
                "QuadUnevenResidual-v0", args.ppo_steps, terrain="rough"
            ),
            # configs/rl/ppo_residual.yaml's exploration: std 0.08 (log_std_init -2.5)
            "QuadUnevenResidual-v0 (rough, std 0.08)": measure_ppo(
                "QuadUnevenResidual-v0", args.ppo_steps, log_std_init=-2.5, terrain="rough"
            ),
            "Ant-v5": measure_ppo("Ant-v5", args.ppo_steps),
        }
        ant = rows["Ant-v5"]["env_steps_per_s"]
        print(f"SB3 PPO training, 2 envs (DummyVecEnv), {args.ppo_steps} env steps each, torch 1 thread")
        print(f"{'env':46s} {'env steps/s':>12s} {'x Ant-v5':>9s}")
        for name, r in rows.items():
            print(f"{name:46s} {r['env_steps_per_s']:12.0f} {r['env_steps_per_s'] / ant:9.2f}")
        print("target for QuadUneven-v0: >= 0.5 x Ant-v5")


if __name__ == "__main__":
    main()
