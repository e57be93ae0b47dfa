"""Two evaluations of the same episodes side by side: a baseline (e.g. the expert) and a candidate (e.g. a residual).

:func:`compare_runs` pairs the episodes of two ``quad-uneven evaluate`` output folders by (entry, seed),
refuses runs that do not hold the same episodes, and computes per policy: success and failure rates,
falls, divergences and stalls, the stability index figures and the mean residual torque, overall, per
terrain entry and per randomization factor (the report's bins of the drawn values), plus the
episodes whose outcome differs and the paired test of the success counts (McNemar's exact test: of the
episodes where the two differ, how lopsided the split is). Several folder pairs (the same suite evaluated
with different ``--seed`` offsets) pool into one comparison. :func:`write_comparison` writes
``comparison.md``, ``comparison.json`` and ``comparison.png``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.machine import machines_differ
from agents.evaluation.metrics import factor_bins, json_safe
from agents.evaluation.results_io import load_results
from agents.outputs import OutputError, output_dir, write_json_atomic
from quad_uneven_env.fields import excerpt

FAILURE_KINDS = ("fall", "diverged", "stall", "error")
"""How an episode that missed the goal ended: a fall (or leaving the terrain), a divergence, a stall (time or
wall-time limit short of the goal), or an error of the policy."""


class ComparisonError(ValueError):
    """Two evaluation folders that cannot be compared; the message names the folder or the field."""


def failure_kind(record: Mapping[str, Any]) -> str | None:
    """None for a success, else one of :data:`FAILURE_KINDS`."""
    if record["success"]:
        return None
    reason = record.get("end_reason")
    if reason in ("fall", "left_terrain"):
        return "fall"
    if reason == "diverged":
        return "diverged"
    if reason == "error":
        return "error"
    return "stall"


def _mean(values: Sequence[float | None]) -> float | None:
    xs = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.mean(xs)) if xs else None


def group_figures(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Figures of a group of episodes: counts and rates (0-1), index figures (N m, s), residual torque (N m)."""
    n = len(records)
    kinds = [failure_kind(r) for r in records]
    successes = [r for r in records if r["success"]]
    return {
        "episodes": n,
        "successes": len(successes),
        "success_rate": len(successes) / n if n else None,
        "failure_rate": (n - len(successes)) / n if n else None,
        **{f"{k}s" if k != "diverged" else "divergences": kinds.count(k) for k in FAILURE_KINDS},
        "mean_stability_index": _mean([r.get("mean_stability_index") for r in records]),
        "min_stability_index": min(
            (float(r["min_stability_index"]) for r in records if r.get("min_stability_index") is not None),
            default=None,
        ),
        "mean_time_index_negative": _mean([r.get("time_index_negative") for r in records]),
        "mean_fraction_index_nonnegative": _mean([r.get("fraction_index_nonnegative") for r in records]),
        "successes_index_ok": sum(1 for r in successes if (r.get("fraction_index_nonnegative") or 0.0) >= 0.99),
        "mean_speed": _mean([r.get("mean_speed") for r in records]),
        "mean_residual_torque": _mean([r.get("mean_residual_torque") for r in records]),
    }


def _paired(base: Mapping[str, Any], cand: Mapping[str, Any], names: tuple[str, str]) -> list[tuple[dict, dict]]:
    def by_key(run: Mapping[str, Any]) -> dict[tuple[int, int], dict]:
        return {(int(e["entry"]), int(e["seed"])): e for e in run["episodes"]}

    a, b = by_key(base), by_key(cand)
    if set(a) != set(b):
        only = sorted(set(a) ^ set(b))[:3]
        raise ComparisonError(
            f"episodes: {names[0]} and {names[1]} do not hold the same (entry, seed) episodes (e.g. {only}); "
            "evaluate both on the same suite with the same --seed and --episodes"
        )
    if base["meta"].get("entries") != cand["meta"].get("entries"):
        raise ComparisonError(f"suite: {names[0]} and {names[1]} were run on different suite entries")
    return [(a[k], b[k]) for k in sorted(a)]


def mcnemar_exact_p(fixed: int, broken: int) -> float:
    """Two-sided p-value of McNemar's exact test: the probability, if neither policy were better, of a split of
    the ``fixed + broken`` discordant episodes at least as uneven as this one (binomial, p = 1/2).

    :param fixed: episodes the baseline failed and the candidate succeeded in.
    :param broken: episodes the baseline succeeded in and the candidate failed.
    """
    if fixed < 0 or broken < 0:
        raise ValueError(f"fixed and broken must be counts >= 0, got {excerpt(fixed)} and {excerpt(broken)}")
    n = fixed + broken
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(min(fixed, broken) + 1))
    return min(1.0, 2.0 * tail / 2**n)


def paired_outcomes(pairs: Sequence[tuple[Mapping[str, Any], Mapping[str, Any]]]) -> dict[str, Any]:
    """The paired success figures of (baseline, candidate) episode records: ``fixed`` (baseline failed,
    candidate succeeded), ``broken`` (the reverse), ``mcnemar_p`` (:func:`mcnemar_exact_p`) and
    ``failure_ratio`` (the candidate's failures over the baseline's; None if the baseline never failed)."""
    fixed = sum(1 for a, b in pairs if not a["success"] and b["success"])
    broken = sum(1 for a, b in pairs if a["success"] and not b["success"])
    failures = [sum(1 for r in side if not r["success"]) for side in zip(*pairs, strict=True)] if pairs else [0, 0]
    return {
        "fixed": fixed,
        "broken": broken,
        "mcnemar_p": mcnemar_exact_p(fixed, broken),
        "failure_ratio": failures[1] / failures[0] if failures[0] else None,
    }


PUSH_FACTORS = ("push_count", "push_impulse_max")
"""Factors that count what happened, not what was drawn: an episode that ends early receives fewer pushes."""


def shared_push_factors(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, float] | None:
    """The push factors of a pair over the pushes both episodes received (count, largest impulse in N s).

    Both episodes draw the same pushes from the same world until the first of them ends, so their push lists
    share a prefix; binning a pair by one side's own pushes would put that side's early falls into the
    "fewest pushes" group and credit the other side there. None if either record has no push list.
    """
    pa, pb = a.get("pushes"), b.get("pushes")
    if pa is None or pb is None:
        return None
    shared = []
    for x, y in zip(pa, pb, strict=False):
        if (x["start"], x["impulse"]) != (y["start"], y["impulse"]):
            break
        shared.append(float(x["impulse"]))
    return {"push_count": float(len(shared)), "push_impulse_max": max(shared, default=0.0)}


def _pair_factors(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, float]:
    """The drawn factors of a pair (the baseline's record; both drew the same world), pushes as both received."""
    factors = dict(a.get("factors") or {})
    shared = shared_push_factors(a, b) if factors else None
    if shared is not None:
        factors.update({k: shared[k] for k in PUSH_FACTORS if k in factors})
    return factors


def _factor_groups(pairs: Sequence[tuple[dict, dict]]) -> list[dict[str, Any]]:
    """Per factor, the paired episodes in the report's bins of the drawn value (:func:`factor_bins`); pushes by
    :func:`shared_push_factors`."""
    factors = [_pair_factors(a, b) for a, b in pairs]
    names = sorted({k for f in factors for k in f})
    rows = []
    for name in names:
        items = [(f[name], a, b) for f, (a, b) in zip(factors, pairs, strict=True) if f.get(name) is not None]
        values = np.array([v for v, _, _ in items])
        for label, group in factor_bins(name, values):
            g = [items[i] for i in group]
            rows.append(
                {
                    "factor": name,
                    "bin": label,
                    "low": float(values[group].min()),
                    "high": float(values[group].max()),
                    "baseline": group_figures([a for _, a, _ in g]),
                    "candidate": group_figures([b for _, _, b in g]),
                }
            )
    return rows


def _folders(value: str | Path | Sequence[str | Path], who: str) -> list[Path]:
    folders = [Path(value)] if isinstance(value, str | Path) else [Path(v) for v in value]
    if not folders:
        raise ComparisonError(f"{who}: no evaluation folder given")
    return folders


def _policies(runs: Sequence[Mapping[str, Any]]) -> Any:
    """The policy of pooled runs: one name, or the distinct names in order (the same model copied elsewhere)."""
    names = list(dict.fromkeys(run.get("policy") for run in runs))
    return names[0] if len(names) == 1 else names


def compare_runs(
    baseline: str | Path | Sequence[str | Path], candidate: str | Path | Sequence[str | Path]
) -> dict[str, Any]:
    """The comparison of two evaluations holding the same episodes.

    :param baseline: an evaluation folder, or several of the same suite (e.g. ``--seed 100`` and ``--seed 300``),
        pooled.
    :param candidate: one folder per baseline folder, in the same order, holding the same episodes as it.
    :return: ``{"baseline": {"dir", "policy", "suite"}, "candidate": {...}, "seed_offset", "overall":
        {"baseline": figures, "candidate": figures, "paired": paired figures}, "by_entry": [...], "by_factor":
        [...], "changed": [episodes whose outcome differs]}`` (figures: :func:`group_figures`; paired:
        :func:`paired_outcomes`; ``dir`` and ``seed_offset`` are lists when several folders are pooled, and ``policy``
        when the pooled runs name different policies).
    :raises ResultsError: on a missing results.json or one that is not an evaluation's (file and field named:
        :func:`agents.evaluation.results_io.load_results`).
    :raises ComparisonError: on runs of different episodes, an unequal number of folders, folders of other suite
        entries, or the same episode in two pooled folders.
    """
    base_dirs, cand_dirs = _folders(baseline, "baseline"), _folders(candidate, "candidate")
    if len(base_dirs) != len(cand_dirs):
        raise ComparisonError(
            f"candidate: {len(cand_dirs)} folder(s) for {len(base_dirs)} baseline folder(s); give one candidate "
            "folder per baseline folder, in the same order"
        )
    bases, cands = [load_results(d) for d in base_dirs], [load_results(d) for d in cand_dirs]
    pairs: list[tuple[dict, dict]] = []
    where: dict[tuple[int, int], Path] = {}
    for base_dir, cand_dir, base, cand in zip(base_dirs, cand_dirs, bases, cands, strict=True):
        if base["meta"].get("entries") != bases[0]["meta"].get("entries"):
            raise ComparisonError(f"suite: {base_dir} and {base_dirs[0]} were run on different suite entries")
        for a, b in _paired(base, cand, (str(base_dir), str(cand_dir))):
            key = (int(a["entry"]), int(a["seed"]))
            if key in where:
                raise ComparisonError(
                    f"episodes: {where[key]} and {base_dir} both hold entry {key[0]}, seed {key[1]}; pool "
                    "evaluations of different seeds (--seed)"
                )
            where[key] = base_dir
            pairs.append((a, b))
    base, cand = bases[0], cands[0]
    pooled = len(base_dirs) > 1
    labels = base["meta"].get("entries") or []
    by_entry = []
    for entry in sorted({a["entry"] for a, _ in pairs}):
        sel = [(a, b) for a, b in pairs if a["entry"] == entry]
        by_entry.append(
            {
                "entry": entry,
                "label": labels[entry] if entry < len(labels) else str(entry),
                "baseline": group_figures([a for a, _ in sel]),
                "candidate": group_figures([b for _, b in sel]),
            }
        )
    changed = [
        {
            "entry": a["entry"],
            "seed": a["seed"],
            "baseline": failure_kind(a) or "success",
            "candidate": failure_kind(b) or "success",
            "factors": a.get("factors"),
        }
        for a, b in pairs
        if bool(a["success"]) != bool(b["success"]) or failure_kind(a) != failure_kind(b)
    ]
    offsets = [run["meta"].get("seed_offset") for run in bases]
    return {
        "baseline": {
            "dir": [str(d) for d in base_dirs] if pooled else str(base_dirs[0]),
            "policy": _policies(bases),
            "suite": base.get("suite"),
        },
        "candidate": {
            "dir": [str(d) for d in cand_dirs] if pooled else str(cand_dirs[0]),
            "policy": _policies(cands),
            "suite": cand.get("suite"),
        },
        "seed_offset": offsets if pooled else offsets[0],
        "overall": {
            "baseline": group_figures([a for a, _ in pairs]),
            "candidate": group_figures([b for _, b in pairs]),
            "paired": paired_outcomes(pairs),
        },
        "by_entry": by_entry,
        "by_factor": _factor_groups(pairs),
        "changed": changed,
        "machines_differ": machines_differ([a for a, _ in pairs], [b for _, b in pairs]),
    }


def _f(value: Any, fmt: str = ".3g") -> str:
    if value is None:
        return "–"
    return format(value, fmt) if isinstance(value, float) else str(value)


_COLUMNS = (
    ("success", lambda g: f"{_f(100 * g['success_rate'], '.0f')}% ({g['successes']}/{g['episodes']})"),
    ("falls", lambda g: str(g["falls"])),
    ("divergences", lambda g: str(g["divergences"])),
    ("stalls", lambda g: str(g["stalls"])),
    ("mean index (N m)", lambda g: _f(g["mean_stability_index"])),
    ("time index < 0 (s)", lambda g: _f(g["mean_time_index_negative"])),
    ("index >= 0 (fraction)", lambda g: _f(g["mean_fraction_index_nonnegative"], ".4f")),
    ("successes >= 99 %", lambda g: str(g["successes_index_ok"])),
    ("residual (N m)", lambda g: _f(g["mean_residual_torque"])),
)


def policy_label(policy: Any, quote: str = "") -> str:
    """A comparison's policy as text: its name, or the pooled runs' names joined (each within ``quote``)."""
    return ", ".join(f"{quote}{p}{quote}" for p in (policy if isinstance(policy, list) else [policy]))


def _rows(label: str, row: Mapping[str, Any]) -> list[str]:
    out = []
    for who in ("baseline", "candidate"):
        cells = [fn(row[who]) for _, fn in _COLUMNS]
        out.append(f"| {label if who == 'baseline' else ''} | {who} | " + " | ".join(cells) + " |")
    return out


def machine_note(differ: Sequence[str] | None) -> list[str]:
    """Markdown lines saying whether the two runs were made on one machine kind (``differ``: the fields of
    :func:`agents.evaluation.machine.machine_info` that differ; None: not recorded)."""
    if differ is None:
        return ["Machines: not recorded for one of the runs (made before the records had them).", ""]
    if not differ:
        return ["Machines: one machine kind and library versions for both runs.", ""]
    return [
        f"**Machines differ** ({', '.join(differ)}): floating-point results differ between machines, and an episode "
        "near a fall can end the other way on another one. Re-run both on one machine for an exact pairing.",
        "",
    ]


def comparison_markdown(comp: Mapping[str, Any]) -> str:
    """The comparison as a Markdown page."""
    head = "| group | policy | " + " | ".join(c for c, _ in _COLUMNS) + " |"
    sep = "|---" * (len(_COLUMNS) + 2) + "|"
    b, c = comp["baseline"], comp["candidate"]
    pooled = isinstance(comp["seed_offset"], list)
    offsets = ", ".join(map(str, comp["seed_offset"])) if pooled else comp["seed_offset"]
    paired = comp["overall"]["paired"]
    ratio = paired["failure_ratio"]
    lines = [
        f"# Comparison on `{b['suite']}` (seed offset{'s' if pooled else ''} {offsets})",
        "",
        f"- baseline: {policy_label(b['policy'], '`')} ({', '.join(b['dir']) if pooled else b['dir']})",
        f"- candidate: {policy_label(c['policy'], '`')} ({', '.join(c['dir']) if pooled else c['dir']})",
        "",
        "The same episodes (entry, seed: the same terrain and the same drawn world) for both. Failures: falls "
        "(and leaving the terrain), divergences, stalls (time limit short of the goal), errors. Index figures are "
        "the evaluation's (N m; fraction of the episode's time with index >= 0).",
        "",
        *machine_note(comp.get("machines_differ")),
        "## Overall",
        "",
        head,
        sep,
        *_rows("all", comp["overall"]),
        "",
        f"Paired: the candidate succeeds in {paired['fixed']} episodes the baseline fails and fails in "
        f"{paired['broken']} the baseline succeeds in (McNemar's exact test, two-sided: p = "
        f"{paired['mcnemar_p']:.3g}); its failures are {_f(ratio, '.2f')} x the baseline's.",
        "",
        "## By terrain entry",
        "",
        head,
        sep,
    ]
    for row in comp["by_entry"]:
        lines += _rows(f"[{row['entry']}] {row['label']}", row)
    if comp["by_factor"]:
        lines += [
            "",
            "## By randomization factor (the report's bins of the drawn values)",
            "",
            "Pushes: the pushes both episodes of a pair received (the same draws until the first of them ends).",
            "",
            head,
            sep,
        ]
        for row in comp["by_factor"]:
            lines += _rows(f"{row['factor']} {row['bin']} ({row['low']:.3g}–{row['high']:.3g})", row)
    lines += ["", "## Episodes whose outcome differs", ""]
    if comp["changed"]:
        lines += ["| entry | seed | baseline | candidate |", "|---|---|---|---|"]
        lines += [f"| {e['entry']} | {e['seed']} | {e['baseline']} | {e['candidate']} |" for e in comp["changed"]]
    else:
        lines.append("None: every episode ended the same way for both.")
    return "\n".join(lines) + "\n"


def plot_comparison(comp: Mapping[str, Any], path: Path) -> Path:
    """Bars per terrain entry: success rate and mean time with index < 0, baseline vs candidate."""
    from agents.plotting import pyplot, save

    rows = [*comp["by_entry"], {"label": "all", "entry": "all", **comp["overall"]}]
    x = np.arange(len(rows))
    fig, axes = pyplot().subplots(1, 2, figsize=(11, 4))
    for ax, key, ylabel in (
        (axes[0], "success_rate", "success rate"),
        (axes[1], "mean_time_index_negative", "mean time with index < 0 (s)"),
    ):
        for k, who in enumerate(("baseline", "candidate")):
            vals = [r[who][key] if r[who][key] is not None else np.nan for r in rows]
            ax.bar(x + (k - 0.5) * 0.38, vals, width=0.38, label=f"{who}: {policy_label(comp[who]['policy'])}")
        ax.set_xticks(x, [f"[{r['entry']}]" for r in rows])
        ax.set_ylabel(ylabel)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylim(0, 1.05)
    axes[0].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"{comp['baseline']['suite']}: baseline vs candidate, same episodes")
    return save(fig, path)


def write_comparison(comp: Mapping[str, Any], out: str | Path) -> dict[str, Path]:
    """Write ``comparison.md``, ``comparison.json`` and ``comparison.png`` into ``out`` (created; these files are
    replaced, others kept).

    :raises OutputError: if ``out`` is a file, cannot be created or the files cannot be written (named).
    """
    out = Path(out)
    paths = {"md": out / "comparison.md", "json": out / "comparison.json", "png": out / "comparison.png"}
    try:
        with output_dir(out, "compare", keep=True) as manifest:
            paths["md"].write_text(comparison_markdown(comp))
            write_json_atomic(paths["json"], json_safe(comp))
            plot_comparison(comp, paths["png"])
            manifest.add(paths.values())
    except OSError as err:
        raise OutputError(f"--out {str(out)!r}: cannot write the comparison ({err})") from None
    return paths


__all__ = [
    "FAILURE_KINDS",
    "ComparisonError",
    "compare_runs",
    "comparison_markdown",
    "failure_kind",
    "group_figures",
    "mcnemar_exact_p",
    "paired_outcomes",
    "plot_comparison",
    "policy_label",
    "write_comparison",
]
