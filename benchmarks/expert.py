"""Speed of the expert in the loop: simulated seconds per wall second on rough terrain.

Measured in one run, on the same model: (1) the expert walking (planner every gait cycle +
computed-torque controller at every 2 ms physics step, through QuadUneven-v0's hook);
(2) the same model stepped with zero torques by raw ``mj_step`` from the same standing state
(restarted every 2 s so it keeps simulating contacts rather than a pile on the ground).
Targets: expert >= 0.6 x the zero-torque rate and >= 25 x real time.

Usage: ``python benchmarks/expert.py [--seconds 30] [--terrain rough] [--model nominal|oracle] [--copy] [--split]
[--hook-cpu] [--no-lane] [--readable] [--paths REPS]`` (``--copy``: the nominal expert copies the measured state into
its own model every physics step even in the nominal world, as it does whenever the simulated robot differs from the
nominal one; ``--split``: also time ``mj_step1`` and ``mj_step2`` inside the env's loop and print where each physics
step's time goes;
``--hook-cpu``: the expert hook's CPU time (``time.thread_time_ns``, which a preempting process on a shared machine
does not inflate the way it does wall time), split into planning, the plans' reference grids and the rest;
``--no-lane``: without the hook's fast lane, ``ExpertPolicy.torques_into``; ``--readable``: the controller's readable
call at every physics step instead of its compiled step (``hook.compiled = False``); ``--paths REPS``: afterwards the
same episode with the readable call, the compiled step without the lane and with it, walked in lockstep in this
process (the machine's load then falls on all alike), REPS times, with their speed-up over the readable call).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import mujoco
import numpy as np

import quad_uneven_env  # noqa: F401
from agents.expert import attach_expert


def main(argv: list[str] | None = None) -> None:
    """Run both measurements and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="simulated seconds of walking")
    parser.add_argument("--terrain", default="rough")
    parser.add_argument("--distribution", default="qp", choices=["qp", "pinv"])
    parser.add_argument("--model", default="nominal", choices=["nominal", "oracle"])
    parser.add_argument("--copy", action="store_true", help="never share the simulator's data (nominal model)")
    parser.add_argument("--split", action="store_true", help="time mj_step1/mj_step2 in the env's loop too")
    parser.add_argument("--hook-cpu", action="store_true", help="CPU time of the expert's hook, split")
    parser.add_argument("--no-lane", action="store_true", help="without the hook's fast lane (torques_into)")
    parser.add_argument("--readable", action="store_true", help="the readable controller call at every physics step")
    parser.add_argument(
        "--paths", type=int, default=0, metavar="REPS",
        help="then walk the same episode with each control path (readable, compiled, compiled + lane) REPS times",
    )  # fmt: skip
    args = parser.parse_args(argv)
    split = _StepTimer.install() if args.split else None
    hook_cpu = _HookCPU.install() if args.hook_cpu else None

    from agents.expert import ExpertConfig

    env = gym.make("QuadUneven-v0", terrain=args.terrain, max_episode_steps=10**7)
    config = ExpertConfig(distribution=args.distribution, model=args.model, share_nominal_world=not args.copy)
    policy = attach_expert(env, config)
    if args.no_lane:
        policy.torques_into = _declines  # the env then makes the hook's full call at every physics step
    if args.readable:
        policy.hook.compiled = False
    # Warm-up: numba kernels compile on first use; keep that out of the timing.
    obs, _ = env.reset(seed=1)
    for _ in range(5):
        obs, *_ = env.step(policy.predict(obs)[0])
    if hook_cpu is not None:
        hook_cpu.wrap(env.unwrapped, policy)
    obs, info = env.reset(seed=0)
    if split is not None:
        split.clear()
    if hook_cpu is not None:
        hook_cpu.clear()
    u = env.unwrapped
    standing = mujoco.MjData(u.model)
    standing.qpos[:] = u.data.qpos
    x0 = info["cog"][0]
    n = int(args.seconds / u.dt)
    t0 = time.perf_counter()
    for _ in range(n):
        obs, _, terminated, _, info = env.step(policy.predict(obs)[0])
        if terminated:
            break
    wall_expert = time.perf_counter() - t0
    sim_expert = u.data.time
    if split is not None:
        split.uninstall()
    if hook_cpu is not None:
        hook_cpu.uninstall()
    planner_s = sum(policy.planner_times_ms) / 1e3

    d = mujoco.MjData(u.model)
    steps = round(sim_expert / u.model.opt.timestep)
    per_restart = round(2.0 / u.model.opt.timestep)
    wall_zero = 0.0
    done = 0
    while done < steps:
        mujoco.mj_resetData(u.model, d)
        d.qpos[:] = standing.qpos
        mujoco.mj_forward(u.model, d)
        k = min(per_restart, steps - done)
        t1 = time.perf_counter()
        for _ in range(k):
            mujoco.mj_step(u.model, d)
        wall_zero += time.perf_counter() - t1
        done += k
    rate_expert = sim_expert / wall_expert
    rate_zero = sim_expert / wall_zero
    print(
        f"terrain {args.terrain}, distribution {args.distribution}, model {args.model} "
        f"({'simulator data shared' if policy.shares_simulator_data else 'own copy'}), {sim_expert:.1f} s simulated"
    )
    print(f"expert walked {info['cog'][0] - x0:.2f} m, ended: {info['termination_reason'] or 'no fall'}")
    print(f"{'':34s} {'sim s / wall s':>15s}")
    print(f"{'expert in the loop':34s} {rate_expert:15.1f}")
    print(f"{'zero torques, raw mj_step':34s} {rate_zero:15.1f}")
    print(
        f"ratio expert / zero-torque: {rate_expert / rate_zero:.2f} (target >= 0.6); real-time factor "
        f"{rate_expert:.1f} (target >= 25)"
    )
    print(
        f"planning: {len(policy.planner_times_ms)} plans, {planner_s:.2f} s of the {wall_expert:.2f} s wall "
        f"(median {np.median(policy.planner_times_ms):.0f} ms per cycle)"
    )

    if split is not None and split.steps:
        n = split.steps
        rest = wall_expert - split.step1 - split.step2 - planner_s
        print(
            f"per physics step ({n} steps): {wall_expert / n * 1e6:.0f} us = mj_step1 {split.step1 / n * 1e6:.0f} + "
            f"mj_step2 {split.step2 / n * 1e6:.0f} + planning {planner_s / n * 1e6:.0f} + controller and the "
            f"rest {rest / n * 1e6:.0f}"
        )
    if args.paths:
        _paths(args.terrain, config, args.seconds, args.paths)
    if hook_cpu is not None:
        n = round(sim_expert / u.model.opt.timestep)
        h = hook_cpu
        print(
            f"expert hook, CPU time per physics step ({n} steps): {h.hook / n / 1e3:.1f} us = planning "
            f"{h.plan / n / 1e3:.1f} + reference grids {h.grid / n / 1e3:.1f} + controller and the rest "
            f"{(h.hook - h.plan - h.grid) / n / 1e3:.1f}"
        )


PATHS = {
    "readable": "the readable controller call (the reference)",
    "compiled": "its compiled step, without the lane",
    "lane": "its compiled step, with the lane",
}
"""The expert's control paths ``--paths`` compares: the hook's full call with ``hook.compiled`` off, on, and the
env's fast lane (``torques_into``) in front of it."""
CHUNK = 50
"""control steps per turn of ``--paths``."""


def _declines(model, data, action, out, limit) -> bool:
    """A fast lane that never answers: the env makes the hook's full call."""
    return False


def _paths(terrain: str, config, seconds: float, reps: int) -> None:
    """Walk ``seconds`` from ``reset(seed=0)`` with each of :data:`PATHS` (one env each), in lockstep: turns of
    :data:`CHUNK` control steps, the order rotating, so that the machine's load falls on all alike; ``reps`` times
    with new envs. Print each path's thread CPU time per physics step (which a preempting process does not
    inflate the way it does wall time) and the readable call's over it, turn by turn."""
    times: dict[str, list[float]] = {p: [] for p in PATHS}
    same = True
    for rep in range(reps):
        runs = {}
        for path in PATHS:
            env = gym.make("QuadUneven-v0", terrain=terrain, max_episode_steps=10**7)
            policy = attach_expert(env, config)
            policy.hook.compiled = path != "readable"
            if path != "lane":
                policy.torques_into = _declines
            obs, _ = env.reset(seed=1)  # compile outside the timing
            for _ in range(5):
                obs, *_ = env.step(policy.predict(obs)[0])
            runs[path] = [env, policy, env.reset(seed=0)[0]]
        n = int(seconds / runs["readable"][0].unwrapped.dt)
        order = list(PATHS)
        for k, start in enumerate(range(0, n, CHUNK)):
            r = (k + rep) % len(order)
            for path in order[r:] + order[:r]:
                env, policy, obs = runs[path]
                u, s0 = env.unwrapped, env.unwrapped.data.time
                c0 = time.thread_time()
                for _ in range(min(CHUNK, n - start)):
                    obs, *_ = env.step(policy.predict(obs)[0])
                cpu = time.thread_time() - c0
                runs[path][2] = obs
                times[path].append(cpu / round((u.data.time - s0) / u.model.opt.timestep) * 1e6)
        end = runs["readable"][0].unwrapped.data.qpos
        same = same and all(np.array_equal(runs[p][0].unwrapped.data.qpos, end) for p in PATHS)
    reference = np.array(times["readable"])
    ended = "the same" if same else "DIFFERENT"
    print(f"control paths, {reps} x {seconds:g} s in turns of {CHUNK} control steps (end states {ended}):")
    for path, what in PATHS.items():
        t = np.array(times[path])
        ratio = reference / t
        print(
            f"  {path:9s} CPU us per physics step: median {np.median(t):6.1f}, mean {t.mean():6.1f}; readable / this "
            f"{np.mean(ratio):4.2f} +- {np.std(ratio) / np.sqrt(len(ratio)):.2f} (turns' mean): {what}"
        )


class _HookCPU:
    """CPU time (``time.thread_time_ns``) of the env's physics-rate hook, of the planner
    (``agents.expert.cycle.plan_gait_cycle``) and of the plans' reference grids
    (``planners.reference.Reference.__init__``), each wrapped."""

    def __init__(self) -> None:
        self.hook = self.plan = self.grid = 0

    @classmethod
    def install(cls) -> _HookCPU:
        import agents.expert.cycle as expert_module
        from planners import reference

        timer, clock = cls(), time.thread_time_ns
        init, plan = reference.Reference.__init__, expert_module.plan_gait_cycle

        def timed_init(ref, *args, **kwargs):
            t = clock()
            init(ref, *args, **kwargs)
            timer.grid += clock() - t

        def timed_plan(*args, **kwargs):
            t = clock()
            try:
                return plan(*args, **kwargs)
            finally:
                timer.plan += clock() - t

        timer._originals = (init, plan)
        reference.Reference.__init__ = timed_init
        expert_module.plan_gait_cycle = timed_plan
        return timer

    def wrap(self, env, expert) -> None:
        """Time the hook of ``env`` (unwrapped), whose controller ``expert`` is (after ``attach_expert``): a
        controller that holds it as ``.expert``, forwards the reset and times the call (the env then makes the call
        at every physics step: no fast lane)."""
        timer, clock = self, time.thread_time_ns

        class Timed:
            def __init__(self) -> None:
                self.expert = expert

            def reset(self, model, data, terrain) -> None:
                expert.reset(model, data, terrain)

            def __call__(self, model, data, action):
                t = clock()
                tau = expert(model, data, action)
                timer.hook += clock() - t
                return tau

        env.set_controller(Timed())

    def clear(self) -> None:
        self.hook = self.plan = self.grid = 0

    def uninstall(self) -> None:
        import agents.expert.cycle as expert_module
        from planners import reference

        reference.Reference.__init__, expert_module.plan_gait_cycle = self._originals


class _StepTimer:
    """Wall time of ``mj_step1`` and ``mj_step2`` as the env's physics loop calls them (the ``mujoco`` of
    :mod:`quad_uneven_env.stepper` replaced by a proxy whose two functions time the real ones; every other attribute
    is MuJoCo's)."""

    def __init__(self) -> None:
        self.step1 = self.step2 = 0.0
        self.steps = 0

    @classmethod
    def install(cls) -> _StepTimer:
        import quad_uneven_env.stepper as stepper_module

        timer = cls()
        real, clock = mujoco, time.perf_counter

        class _Proxy:
            def __getattr__(self, name):
                return getattr(real, name)

            @staticmethod
            def mj_step1(m, d):
                t = clock()
                real.mj_step1(m, d)
                timer.step1 += clock() - t
                timer.steps += 1

            @staticmethod
            def mj_step2(m, d):
                t = clock()
                real.mj_step2(m, d)
                timer.step2 += clock() - t

        stepper_module.mujoco = _Proxy()
        return timer

    def clear(self) -> None:
        self.step1 = self.step2 = 0.0
        self.steps = 0

    @staticmethod
    def uninstall() -> None:
        import quad_uneven_env.stepper as stepper_module

        stepper_module.mujoco = mujoco


if __name__ == "__main__":
    main()
