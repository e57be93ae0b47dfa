"""Episodes as Ray tasks (``evaluate``, ``collect``, ``distill`` with ``--backend ray``): one task per episode, on a
local Ray or a cluster.

Each task runs the function the process pool runs (:func:`agents.evaluation.episode.run_task` for ``evaluate``,
``collect``'s recorder, ``distill``'s rollout) and returns its result through Ray's object store; the caller writes
every result as it arrives, so the records, ``--resume`` and interrupts behave as with the process pool.

Ray is the optional ``distributed`` extra: :func:`import_ray` imports it (``import agents`` never
does) and turns its absence into :class:`RayUnavailable`. What travels to the workers: docs/distributed.md.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

from agents.evaluation.episode import EvalConfig, run_task
from agents.evaluation.suites import EpisodeTask
from quad_uneven_env.fields import excerpt

__all__ = [
    "BACKENDS",
    "DEFAULT_LOCAL_CPUS",
    "EXTRA_HINT",
    "SHIPPED",
    "RayUnavailable",
    "absolute_paths",
    "check_backend",
    "code_runtime_env",
    "import_ray",
    "import_tune",
    "map_on_ray",
    "ray_session",
    "run_on_ray",
]

BACKENDS = ("pool", "ray")
"""Where ``evaluate`` runs its episodes: ``pool`` (spawned processes on this machine, ``--workers``) or ``ray``."""

DEFAULT_LOCAL_CPUS = 2
"""CPUs of a local Ray started without ``--address`` when no count is given."""

EXTRA_HINT = 'pip install -e ".[distributed]"'
"""How to install Ray (the ``distributed`` extra of pyproject.toml)."""


SHIPPED = ("agents", "planners", "quad_uneven_env", "configs")
"""Folders of the source tree that ``ship_code`` uploads to the cluster (the Python packages and the configs)."""


def code_runtime_env() -> dict[str, Any]:
    """A Ray ``runtime_env`` that ships this source tree's :data:`SHIPPED` folders to every worker (its
    ``working_dir``: the workers import these packages and read these configs, whatever is installed there).

    :raises ValueError: if the packages do not run from a source tree holding all of :data:`SHIPPED`.
    """
    root = Path(__file__).resolve().parents[2]
    missing = [name for name in SHIPPED if not (root / name).is_dir()]
    if missing:
        raise ValueError(f"ship_code: {root} is not a source tree with {list(SHIPPED)} (missing {missing})")
    keep = {*SHIPPED}
    excludes = [f"/{p.name}" for p in root.iterdir() if p.name not in keep]
    return {"working_dir": str(root), "excludes": [*excludes, "__pycache__", "*.pyc"]}


class RayUnavailable(ValueError):
    """Ray (or Ray Tune) is not installed; the message names the extra that installs it."""


def import_ray(what: str = "--backend ray") -> ModuleType:
    """The ``ray`` module.

    :param what: the command or option that needs it (for the message).
    :raises RayUnavailable: if Ray cannot be imported (one line naming the ``distributed`` extra).
    """
    try:
        import ray
    except ImportError as err:
        raise RayUnavailable(f"{what} needs Ray, the 'distributed' extra: {EXTRA_HINT} ({err})") from None
    return ray


def import_tune(what: str = "sweep") -> ModuleType:
    """The ``ray.tune`` module; :raises RayUnavailable: as :func:`import_ray` (Tune needs ``ray[tune]``)."""
    import_ray(what)
    try:
        from ray import tune
    except ImportError as err:
        raise RayUnavailable(f"{what} needs Ray Tune, the 'distributed' extra: {EXTRA_HINT} ({err})") from None
    return tune


@contextlib.contextmanager
def ray_session(
    address: str | None = None, num_cpus: int | None = None, what: str = "--backend ray", ship_code: bool = False
) -> Iterator[Any]:
    """Inside the block, Ray is initialised: the running session if there is one, else a new one (shut down on exit).

    :param address: a cluster to join (``"auto"``, ``"HOST:6379"`` or ``"ray://HOST:10001"``); None: a local Ray
        on this machine with ``num_cpus`` CPUs (default :data:`DEFAULT_LOCAL_CPUS`) and no dashboard.
    :param num_cpus: CPUs of a local Ray; ignored when joining a cluster (its nodes say their own).
    :param ship_code: a new session uploads this source tree to its workers (:func:`code_runtime_env`); without
        it the workers import the packages installed on their node. A running session keeps its own.

    The SIGTERM handler of this process is kept (``ray.init`` replaces it with one that exits at once), so
    :func:`agents.interrupts.sigterm_as_keyboard_interrupt` still turns SIGTERM into an interrupt.
    :raises RayUnavailable: without Ray; ``ValueError`` if ``num_cpus`` < 1 or the cluster cannot be reached.
    """
    ray = import_ray(what)
    if num_cpus is not None and (isinstance(num_cpus, bool) or not isinstance(num_cpus, int) or num_cpus < 1):
        raise ValueError(f"num_cpus must be an integer >= 1, got {excerpt(num_cpus)}")
    if ray.is_initialized():
        yield ray
        return
    kwargs: dict[str, Any] = {"include_dashboard": False, "logging_level": logging.WARNING}
    if ship_code:
        kwargs["runtime_env"] = code_runtime_env()
    if address is None:
        kwargs["num_cpus"] = num_cpus or DEFAULT_LOCAL_CPUS
    else:
        kwargs["address"] = address
    main_thread = threading.current_thread() is threading.main_thread()
    sigterm = signal.getsignal(signal.SIGTERM) if main_thread else None
    try:
        ray.init(**kwargs)
    except (ConnectionError, RuntimeError) as err:
        raise ValueError(f"--address {address!r}: cannot join the Ray cluster ({err})") from None
    finally:
        if main_thread:  # ray.init installs a SIGTERM -> sys.exit handler: keep ours (SIGTERM as Ctrl-C)
            signal.signal(signal.SIGTERM, sigterm)
    try:
        yield ray
    finally:
        ray.shutdown()


def check_backend(backend: str, address: str | None, ship_code: bool) -> None:
    """Check a command's backend options; with ``backend="ray"``, import Ray (fail before anything is written).

    :raises ValueError: on an unknown backend, or ``address``/``ship_code`` without ``backend="ray"``.
    :raises RayUnavailable: with ``backend="ray"`` and no Ray.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {list(BACKENDS)}, got {excerpt(backend)}")
    if (address is not None or ship_code) and backend != "ray":
        raise ValueError(f"address and ship_code are for backend 'ray' only, got backend {excerpt(backend)}")
    if backend == "ray":
        import_ray()


def absolute_paths(cfg: EvalConfig) -> EvalConfig:
    """``cfg`` with its file paths (a model file, the video folder) made absolute: a Ray worker's working
    directory need not be this process's."""
    policy = cfg.policy
    if policy not in ("zero", "expert") and Path(policy).exists():
        policy = str(Path(policy).resolve())
    video_dir = None if cfg.video_dir is None else str(Path(cfg.video_dir).resolve())
    return dataclasses.replace(cfg, policy=policy, video_dir=video_dir)


def map_on_ray(
    fn: Callable[..., Any],
    items: Sequence[Any],
    on_result: Callable[[int, Any], None],
    shared: tuple[Any, ...] = (),
    address: str | None = None,
    num_cpus: int | None = None,
    ship_code: bool = False,
) -> None:
    """``fn(item, *shared)`` of every item as a Ray task (1 CPU each), handing ``on_result(position, value)`` each
    value as it finishes (``position``: the item's index in ``items``).

    ``fn`` must be a module-level function (the workers import it); ``shared`` goes to Ray's object store once.
    Joins the running Ray session, else starts one (see :func:`ray_session`, also for ``ship_code``). An error
    in ``on_result`` or an interrupt cancels the tasks not yet finished; the values already handed on are the caller's.

    :raises RayUnavailable: without Ray.
    """
    if not items:
        return
    with ray_session(address, num_cpus, ship_code=ship_code) as ray:
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        refs = [ray.put(value) for value in shared]
        pending = [remote.remote(item, *refs) for item in items]
        position = {ref: i for i, ref in enumerate(pending)}
        try:
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                on_result(position[ready[0]], ray.get(ready[0]))
        except BaseException:  # an error or an interrupt: do not wait for the running tasks
            for ref in pending:
                ray.cancel(ref, force=True)
            raise


def run_on_ray(
    tasks: Sequence[EpisodeTask],
    cfg: EvalConfig,
    on_result: Callable[[Any], None],
    address: str | None = None,
    num_cpus: int | None = None,
    ship_code: bool = False,
    runner: Callable[[EpisodeTask, EvalConfig], Any] = run_task,
) -> None:
    """Run every episode task as a Ray task (:func:`map_on_ray`), handing each result to ``on_result`` as it finishes.

    :param runner: the episode function, ``runner(task, cfg)`` (default :func:`run_task`, whose result is an
        :class:`EpisodeResult`; a module-level function).
    :raises RayUnavailable: without Ray.
    """
    map_on_ray(runner, tasks, lambda _, result: on_result(result), (absolute_paths(cfg),), address, num_cpus, ship_code)
