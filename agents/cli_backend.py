"""The ``--workers``, ``--backend``, ``--address`` and ``--ship-code`` options of the commands whose episodes can run
on Ray (``collect``, ``distill``, ``baselines``; docs/distributed.md), and their check."""

from __future__ import annotations

import argparse

from agents.evaluation.ray_backend import BACKENDS, DEFAULT_LOCAL_CPUS

__all__ = ["add_backend_arguments", "backend_options"]


def add_backend_arguments(p: argparse.ArgumentParser, what: str = "episode") -> None:
    """Register ``--workers``, ``--backend``, ``--address`` and ``--ship-code`` on ``p``.

    :param what: what runs in parallel, for the help ("episode", "rollout").
    """
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help=f"parallel {what} processes (default 1; the same result); with --backend ray and no --address: the "
        f"CPUs of the local Ray (default {DEFAULT_LOCAL_CPUS})",
    )
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        default="pool",
        help=f"where the {what}s run: 'pool' (processes on this machine, default) or 'ray' (one Ray task per "
        f"{what}; needs the 'distributed' extra; docs/distributed.md)",
    )
    p.add_argument(
        "--address",
        default=None,
        help="with --backend ray: the Ray cluster to join ('auto', HOST:6379 or ray://HOST:10001); default: a "
        "local Ray",
    )
    p.add_argument(
        "--ship-code",
        action="store_true",
        help="with --backend ray: upload this source tree (packages and configs) to the Ray workers instead of "
        "using the package installed on each node",
    )


def backend_options(args: argparse.Namespace) -> dict:
    """``workers``, ``backend``, ``address`` and ``ship_code`` of the parsed options, checked.

    :raises ValueError: on ``--workers`` < 1, ``--address``/``--ship-code`` without ``--backend ray``, or
        ``--workers`` with ``--address`` (the cluster has its own CPUs).
    """
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if (args.address is not None or args.ship_code) and args.backend != "ray":
        raise ValueError("--address and --ship-code need --backend ray")
    if args.workers is not None and args.address is not None:
        raise ValueError(
            f"--workers sets the processes here or the CPUs of a local Ray; the cluster given by --address "
            f"{args.address!r} has its own CPUs: drop --workers {args.workers}"
        )
    workers = args.workers if args.workers is not None else DEFAULT_LOCAL_CPUS if args.backend == "ray" else 1
    return {"workers": workers, "backend": args.backend, "address": args.address, "ship_code": args.ship_code}
