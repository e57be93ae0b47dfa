"""What every figure of the project shares: leg colours, gait-phase shading, the headless backend, saving.

All plotting goes through :func:`pyplot` (matplotlib with the non-interactive Agg backend, imported
on first use so that importing a module that plots stays cheap) and :func:`save`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

LEG_COLOURS: dict[str, str] = {"LF": "tab:blue", "RF": "tab:orange", "LH": "tab:green", "RH": "tab:red"}
"""Colour of each leg in every figure."""

LEG_LINESTYLES: dict[str, str] = {"LF": "-", "RF": "--", "LH": "-", "RH": "--"}
"""Line style of each leg where left and right legs overlap (side views)."""


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the headless Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig: Any, path: Path, dpi: int = 130, tight: bool = True, bbox_tight: bool = False) -> Path:
    """Write ``fig`` to ``path`` (PNG at ``dpi``) and close it; returns ``path``."""
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=dpi, **({"bbox_inches": "tight"} if bbox_tight else {}))
    pyplot().close(fig)
    return Path(path)


def shade_phases(
    ax: Any,
    phases: Sequence[Any],
    *,
    boundary_style: str = ":",
    alpha: float = 0.08,
    shade: bool = True,
    label: bool | str = False,
    t_label_max: float = float("inf"),
) -> None:
    """Gait-phase boundaries as vertical lines and swing phases shaded in the swing leg's colour.

    :param phases: objects with ``t_start``, ``t_end`` (s) and ``swing_leg`` (leg name or None).
    :param label: True: "LF swing" above each swing phase; ``"short"``: the leg name only.
    :param t_label_max: s, no labels for phases ending after this time.
    """
    for ph in phases[:-1]:
        ax.axvline(ph.t_end, color="0.55", lw=0.6, ls=boundary_style, zorder=0)
    for ph in phases:
        if not ph.swing_leg:
            continue
        colour = LEG_COLOURS[ph.swing_leg]
        if shade:
            ax.axvspan(ph.t_start, ph.t_end, color=colour, alpha=alpha, lw=0, zorder=0)
        if label and ph.t_end <= t_label_max + 1e-9:
            text = ph.swing_leg if label == "short" else f"{ph.swing_leg} swing"
            ax.text(0.5 * (ph.t_start + ph.t_end), 1.0, text, transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=7, color=colour)  # fmt: skip
