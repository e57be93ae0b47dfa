"""The layout's rules as tests: layering, no import cycles, no private imports, pure planners, argparse only in
the CLI.

Each rule walks the source with ``ast`` (what a module imports is what it says), so a new module
that breaks a rule fails here, whatever it is named.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("quad_uneven_env", "planners", "agents")
LAYER = {name: i for i, name in enumerate(PACKAGES)}
"""A package may import only packages of a lower layer: agents -> planners -> quad_uneven_env."""


def _modules() -> list[tuple[str, Path]]:
    out = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            out.append((".".join(parts), path))
    return out


def _imports(path: Path) -> list[tuple[int, str, list[str]]]:
    """(line, imported module, imported names) of every import in ``path``, at any depth."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module, [a.name for a in node.names]))
    return found


MODULES = _modules()


def layering_violations(modules=MODULES) -> list[str]:
    bad = []
    for mod, path in modules:
        own = LAYER[mod.split(".")[0]]
        for line, target, _ in _imports(path):
            top = target.split(".")[0]
            if top in LAYER and LAYER[top] > own:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {target} (against agents -> planners -> env)")
    return bad


def private_import_violations(modules=MODULES) -> list[str]:
    bad = []
    for _, path in modules:
        for line, target, names in _imports(path):
            if target.split(".")[0] not in LAYER:
                continue
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            private += [p for p in target.split(".") if p.startswith("_") and not p.startswith("__")]
            if private:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports private {private} from {target}")
    return bad


def argparse_violations(modules=MODULES) -> list[str]:
    return [
        f"{path.relative_to(ROOT)}:{line} imports argparse (parsers belong in agents/cli.py and its agents/cli_*.py)"
        for mod, path in modules
        if mod != "agents.cli" and not mod.startswith("agents.cli_")
        for line, target, _ in _imports(path)
        if target == "argparse"
    ]


def test_imports_follow_the_layers():
    assert layering_violations() == []


def test_no_module_imports_another_modules_private_names():
    assert private_import_violations() == []


def test_only_the_cli_builds_parsers():
    assert argparse_violations() == []


def test_the_rules_catch_a_wrong_import(tmp_path):
    """Each checker flags a module written to break it (so the tests above can fail)."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        "import argparse\nfrom agents.expert import ExpertConfig\nfrom quad_uneven_env.stability import _hidden\n"
    )
    fake = [("quad_uneven_env.bad", bad)]
    global ROOT
    root, ROOT = ROOT, tmp_path
    try:
        assert any("agents.expert" in v for v in layering_violations(fake))
        assert any("_hidden" in v for v in private_import_violations(fake))
        assert argparse_violations(fake)
    finally:
        ROOT = root


def _type_checking_blocks(tree: ast.Module) -> set[int]:
    """ids of the statements under ``if TYPE_CHECKING:`` (never run: no import-time dependency)."""
    guarded: set[int] = set()
    for node in ast.walk(tree):
        test = node.test if isinstance(node, ast.If) else None
        if isinstance(test, ast.Name | ast.Attribute) and ast.unparse(test).endswith("TYPE_CHECKING"):
            guarded |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return guarded


def module_imports(mod: str, path: Path, known: set[str]) -> set[str]:
    """The project modules ``mod`` (at ``path``) imports, at any depth (module level, functions, methods).

    ``import a.b`` and ``from a.b import x`` depend on ``a.b``; ``from a import b`` on the submodule ``a.b`` when
    there is one (else on ``a``, for its name ``b``); relative imports are resolved against ``mod``. Imports under
    ``if TYPE_CHECKING:`` are left out: they never run. A package's parent packages are not counted (every module
    imports its parents first; that is no cycle).
    """
    tree = ast.parse(path.read_text(), str(path))
    guarded = _type_checking_blocks(tree)
    package = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
    out = set()
    for node in ast.walk(tree):
        if id(node) in guarded:
            continue
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name in known}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package[: len(package) - node.level + 1]
                base = ".".join([*parent, *([node.module] if node.module else [])])
            for a in node.names:
                target = f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                if target in known:
                    out.add(target)
    out.discard(mod)
    return out


def import_cycles(modules=MODULES) -> list[list[str]]:
    """Every set of project modules that import each other, directly or through others (the strongly connected
    components of the import graph with more than one module, Tarjan's algorithm), each sorted."""
    known = {m for m, _ in modules}
    graph = {m: sorted(module_imports(m, p, known)) for m, p in modules}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return sorted(cycles)


def test_no_import_cycles():
    """No two modules import each other, at module level or inside a function, directly or through others."""
    assert import_cycles() == []


def _fake_package(tmp_path: Path, files: dict[str, str]) -> list[tuple[str, Path]]:
    modules = []
    for name, text in files.items():
        path = tmp_path / (name.replace(".", "/") + ("/__init__.py" if name in ("pkg", "pkg.sub") else ".py"))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        modules.append((name, path))
    return modules


def test_the_cycle_rule_catches_a_cycle_through_a_function_level_import(tmp_path):
    modules = _fake_package(
        tmp_path,
        {
            "pkg": "",
            "pkg.a": "from pkg.b import f\n",
            "pkg.b": "def f():\n    if True:\n        from pkg import c\n",
            "pkg.c": "import pkg.a\n",
        },
    )
    assert import_cycles(modules) == [["pkg.a", "pkg.b", "pkg.c"]]


def test_the_cycle_rule_tells_a_submodule_from_a_name_and_resolves_relative_imports(tmp_path):
    """``from pkg import mod`` depends on ``pkg.mod``, not on ``pkg`` (whose ``__init__`` imports ``pkg.mod``);
    ``from pkg import name`` on ``pkg``; ``from . import x`` and ``from .x import y`` on ``pkg.sub.x``."""
    modules = _fake_package(
        tmp_path,
        {
            "pkg": "from pkg.kernels import k\nfrom pkg.sub import helper\n",
            "pkg.kernels": "k = 1\n",
            "pkg.user": "from pkg import kernels\n",  # the submodule: no cycle with pkg
            "pkg.sub": "from . import x\nhelper = 1\n",
            "pkg.sub.x": "from .y import z\n",
            "pkg.sub.y": "z = 1\n\ndef g():\n    from pkg import k\n",  # the name k of pkg: pkg -> sub -> x -> y -> pkg
        },
    )
    known = {m for m, _ in modules}
    paths = dict(modules)
    assert module_imports("pkg.user", paths["pkg.user"], known) == {"pkg.kernels"}
    assert module_imports("pkg.sub", paths["pkg.sub"], known) == {"pkg.sub.x"}
    assert module_imports("pkg.sub.x", paths["pkg.sub.x"], known) == {"pkg.sub.y"}
    assert import_cycles(modules) == [["pkg", "pkg.sub", "pkg.sub.x", "pkg.sub.y"]]


def test_the_cycle_rule_leaves_out_type_checking_imports(tmp_path):
    modules = _fake_package(
        tmp_path,
        {
            "pkg": "",
            "pkg.a": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.b import B\n",
            "pkg.b": "from pkg.a import A\n",
        },
    )
    assert import_cycles(modules) == []


def _loaded_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted({{m.split('.')[0] for m in sys.modules}})))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    return set(out.stdout.split())


def test_planners_load_no_simulator_and_no_plotting():
    loaded = _loaded_after("import planners")
    assert loaded.isdisjoint({"mujoco", "gymnasium", "matplotlib", "agents"}), loaded & {"mujoco", "gymnasium"}


def test_import_agents_loads_no_torch_or_sb3():
    loaded = _loaded_after("import agents, agents.evaluation, agents.control")
    assert loaded.isdisjoint({"torch", "stable_baselines3"})


def test_the_cli_and_the_ray_modules_load_no_ray_torch_or_sb3():
    """Ray is an optional extra: only running ``--backend ray`` or ``sweep`` imports it."""
    loaded = _loaded_after("import agents.cli, agents.evaluation.ray_backend, agents.rl.sweep")
    assert loaded.isdisjoint({"ray", "torch", "stable_baselines3"}), loaded & {"ray", "torch", "stable_baselines3"}


def test_gymnasium_imported_after_the_package_still_finds_the_env():
    loaded = _loaded_after(
        "import planners, quad_uneven_env; import gymnasium as gym; gym.make('QuadUneven-v0', terrain='flat')"
    )
    assert "mujoco" in loaded


@pytest.mark.parametrize("mod", [m for m, p in MODULES if p.name == "__init__.py"])
def test_every_package_has_a_front_door(mod):
    path = next(p for m, p in MODULES if m == mod)
    tree = ast.parse(path.read_text())
    assert ast.get_docstring(tree), f"{mod} has no docstring"
    names = [t.id for n in tree.body if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)]
    assert "__all__" in names or mod.count(".") >= 2, f"{mod} has no __all__"


def test_the_cli_docstring_lists_every_command():
    """The ``agents/cli.py`` docstring is the map of the command line: every subcommand appears in it."""
    import agents.cli

    parser = agents.cli.build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices  # argparse's subcommands
    listed = set(re.findall(r"^- ``([a-z-]+)``:", agents.cli.__doc__, re.MULTILINE))
    assert listed == set(commands)


HISTORY = re.compile(r"\b[Ii]ssue \d+|\(issue|section \d+ of|the first version")


def test_no_process_history_in_the_code():
    """Issue numbers and change histories belong in the git log and CHANGELOG.md, not the code."""
    hits = []
    for path in [p for _, p in MODULES] + sorted((ROOT / "tests").rglob("*.py")):
        if path == Path(__file__).resolve():
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if HISTORY.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert hits == []


USER_HISTORY = re.compile(
    r"\b(?:sessions? \d+|issues? #?\d+|runs? \d+(?:-\d+)?(?=[ ,.;:)'])|formerly|pre-\d+\b"
    r"|the (?:first|previous|old) (?:version|code|model|run|commit)"
    r"|(?:before|after) (?:this|the|that) (?:change|fix|commit|session|switch|merge))"
    r"|\((?:before|after)[:)]|\| *(?:before|after) *\|",
    re.IGNORECASE,
)
"""Process history as users meet it: numbered work sessions, training runs and issues, "formerly", the previous
version, and before/after labels of a change. What changed for users goes to CHANGELOG.md, by version."""


def user_facing_text() -> list[Path]:
    """What users read: the README, the guide, configs, the Makefile, model cards and the CLI's help."""
    paths = [ROOT / "README.md", ROOT / "Makefile", ROOT / "agents" / "cli.py"]
    paths += sorted((ROOT / "docs").rglob("*.md")) + sorted((ROOT / "configs").rglob("*.yaml"))
    paths += sorted((ROOT / "models").glob("*/README.md"))
    return [p for p in paths if p.exists()]


def history_hits(paths: list[Path]) -> list[str]:
    return [
        f"{path.relative_to(ROOT)}:{i}: {line.strip()}"
        for path in paths
        for i, line in enumerate(path.read_text().splitlines(), 1)
        if USER_HISTORY.search(line)
    ]


def test_no_process_history_where_users_read():
    assert history_hits(user_facing_text()) == []


@pytest.mark.parametrize(
    "line",
    [
        "the residual baseline (run 7) and runs 8-10",
        "# Session 20: a learned estimator",
        "see issue 12 for the targets",
        "`agents.rl` (formerly `agents.residual`)",
        "measured on the previous version",
        "the pre-13 contact model",
        "| terrain | before | after |",
        "0 falls (before: 3)",
        "two episodes moved after this change",
    ],
)
def test_the_history_rule_catches(line):
    assert USER_HISTORY.search(line)


@pytest.mark.parametrize(
    "line",
    [
        "before the first episode, the env is checked",
        "a run of 30 episodes; --workers 2",
        "runs the episodes as Ray tasks",
        "the first cycle starts from rest",
    ],
)
def test_the_history_rule_lets_ordinary_prose_through(line):
    assert not USER_HISTORY.search(line)
