"""The parameter reference of docs/terrain.md, generated from the kinds' declarations."""

from __future__ import annotations

from quad_uneven_env.terrain.kinds import KINDS
from quad_uneven_env.terrain.params import REQUIRED, Param


def _default(q: Param) -> str:
    if q.default is REQUIRED:
        return "required"
    if q.default is None:
        return "null"
    return f"`{q.default:g}`" if isinstance(q.default, float) else f"`{q.default}`"


def parameter_tables() -> str:
    """Markdown: one section per kind with a table (parameter, default, allowed, unit, meaning)."""
    out = []
    for kind in KINDS.values():
        out.append(f"### `{kind.name}`\n\n{kind.doc}\n")
        out.append("| parameter | default | allowed | unit | meaning |\n|---|---|---|---|---|")
        for q in kind.all_params:
            out.append(f"| `{q.name}` | {_default(q)} | {q.allowed()} | {q.unit} | {q.doc} |")
        out.append("")
    return "\n".join(out)
