"""Inference cost per control step of a network policy: SB3's ``predict`` and onnxruntime on its ONNX export.

A deployment runs the policy once per control step (20 ms). The script loads the model folder as ``quad-uneven
evaluate`` does (observation normalisation included), exports it as ``quad-uneven export`` does, and times one
observation at a time on one thread: SB3's ``predict`` (numpy in, normalisation, torch, clipping), onnxruntime on
the exported graph, and as the reference measured in the same run the env's own step (``QuadUneven-v0`` with the
model's arguments, the default terrain). Observations are the env's, from a short rollout of the policy. Prints
the median time per call (ms) and each one's ratio to the env step; also checks that the two outputs agree.

Usage: ``python benchmarks/policy_inference.py [--policy models/distilled/model.zip] [--calls 2000]`` (needs the
``export`` extra: onnx and onnxruntime).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.evaluation.policies import make_policy
from agents.rl.export import export_onnx
from agents.rl.model_io import make_model_env


def median_ms(fn, args: list, repeats: int) -> float:
    """Median wall time (ms) of ``fn(a)`` over ``repeats`` calls, cycling through ``args``."""
    times = np.empty(repeats)
    for k in range(repeats):
        a = args[k % len(args)]
        t0 = time.perf_counter()
        fn(a)
        times[k] = time.perf_counter() - t0
    return float(np.median(times) * 1e3)


def main() -> None:
    """Print one line per path: median ms per call and its ratio to the env step."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="models/distilled/model.zip")
    parser.add_argument("--calls", type=int, default=2000)
    args = parser.parse_args()
    import onnxruntime as ort

    torch.set_num_threads(1)
    env = make_model_env(args.policy)
    policy = make_policy(args.policy, env)
    obs, _ = env.reset(seed=0)
    observations, actions = [], []
    for _ in range(200):
        action, _ = policy.predict(obs, deterministic=True)
        observations.append(obs)
        actions.append(action)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            obs, _ = env.reset()

    with tempfile.TemporaryDirectory() as tmp:
        onnx_path = export_onnx(args.policy, Path(tmp) / "policy.onnx")
        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        session = ort.InferenceSession(str(onnx_path), options, providers=["CPUExecutionProvider"])
    name = session.get_inputs()[0].name
    batch = [o[None].astype(np.float32) for o in observations]
    onnx_actions = np.concatenate([session.run(None, {name: b})[0] for b in batch])
    gap = float(np.max(np.abs(onnx_actions - np.asarray(actions))))

    env.reset(seed=1)
    step_ms = median_ms(lambda a: env.step(a), actions, min(args.calls, 1000))
    predict_ms = median_ms(lambda o: policy.predict(o, deterministic=True), observations, args.calls)
    onnx_ms = median_ms(lambda b: session.run(None, {name: b}), batch, args.calls)
    print(f"policy {args.policy}: {observations[0].size} inputs; ONNX and predict agree to {gap:.1e}")
    print("path                        ms/call   x env step")
    print(f"env step (reference)        {step_ms:7.3f}   1.00")
    print(f"SB3 predict (torch)         {predict_ms:7.3f}   {predict_ms / step_ms:.3f}")
    print(f"onnxruntime (exported)      {onnx_ms:7.3f}   {onnx_ms / step_ms:.3f}")
    env.close()


if __name__ == "__main__":
    main()
