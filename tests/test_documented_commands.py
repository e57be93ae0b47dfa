"""Every ``quad-uneven ...`` and ``make ...`` command that README.md and docs/*.md show runs as written.

**Discovery** (nothing is listed by hand): the shell code fences (``bash``, ``sh``, ``shell``, ``console``) and the
inline code spans of every page. In a fence, a logical line (``\\`` continuations joined) that starts with
``quad-uneven``, ``.venv/bin/quad-uneven`` or ``make`` is a command; ``for``/``do``/``done`` lines are kept around
them and the block is expanded by bash itself (loops, ``$var``, ``$(...)``, ``{a,b}``), with the two programs
replaced by functions that record their arguments; other programs (``pip``, ``git``, ``ray``) are not this
project's commands. An inline span is a command if it starts with one of the programs and gives more than a
subcommand; one that lacks a required option names an option in the text (``quad-uneven evaluate
--scale-terrain``): a mention. A command holding a placeholder (an upper-case word such as ``NAME``, ``DIR``, ``K``,
or ``...``) is a pattern, and so is every command of a fence that holds one. Patterns and mentions are checked, not
run.

**Checks (default suite, seconds)**, per page: every command parses with the real parser (a pattern or a mention:
its subcommand and every option it names exist); every file it reads is in the checkout or written by an earlier
command of the page; the shortened form that the slow test runs (:data:`SHORTER`) parses too; every ``make``
target exists (``make -n``). Commands that take a few seconds (:data:`CHEAP`) are run.

**Runs (make test-slow)**, per page: the page's commands in order, in a fresh working directory holding copies of
the checkout's data (:data:`CHECKOUT_DATA`, and any other checkout file they name), exactly as written (relative
paths included) but for :data:`SHORTER`; each must exit 0. Not run, with the reason (a warning lists them):
:data:`NOT_RUN` (a Ray cluster, hours of training), ``make`` targets other than :data:`MAKE_RUN` (checked with
``make -n``), commands that need an extra that is not installed (:data:`EXTRAS`), and commands that read what one
of those would have written.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import importlib.metadata
import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

SHELL_LANGUAGES = ("bash", "sh", "shell", "console")
"""Fences whose lines are shell commands."""

PROGRAMS = {"quad-uneven": "quad-uneven", ".venv/bin/quad-uneven": "quad-uneven", "make": "make"}
"""How the pages call the project's programs, and which program that is."""

PLACEHOLDER = re.compile(r"\.\.\.|(?<![\w$])[A-Z][A-Z0-9_]*(?![\w])")
"""A word the reader replaces: ``NAME``, ``DIR``, ``K``, ``SUBCOMMAND``, ``...``."""

OUTPUT_OPTIONS = ("out", "gif", "tensorboard", "plot", "data")
"""Options (argparse dests) whose value a command writes; any other path it is given, it reads."""

SHORTER: dict[str, dict[str, str]] = {
    "evaluate": {"--episodes": "1"},
    "collect": {"--episodes": "1"},
    "select": {"--episodes": "1"},
    "train": {"--time-limit-min": "0.5"},
    "distill": {"--suite": "smoke", "--episodes": "1", "--dagger-rounds": "1", "--epochs": "1"},
    "robustness": {"--seeds": "1"},
    "baselines": {"--episodes": "1"},
    "demo": {"--distance": "0.5"},
}
"""The substitutions of the slow run, per subcommand: each option set to this value (added if absent). One seed per
suite entry; trainings stop (and save their model) after 30 s of training; the distillation on the smoke suite with
one DAgger round and one epoch; one seed per robustness value and per baselines suite entry; the demo walks 0.5 m."""

NOT_RUN: dict[str, Callable[[argparse.Namespace], bool]] = {
    "it needs a running Ray cluster (--address)": lambda a: getattr(a, "address", None) is not None,
    "it trains 4 runs of 30,000 steps (tests/agents/test_sweep.py runs a sweep)": lambda a: a.command == "sweep",
}
"""Commands the slow run does not run, checked as above: the reason, and which commands."""

MAKE_RUN: dict[str, tuple[str, ...]] = {"demo": ("OUT=out/demo",)}
"""``make`` targets the slow run runs, on the first page that shows them (from the checkout, the venv taken as
installed, outputs in the working directory); the others (test, test-slow, docs, venv, the trainings: minutes to
hours, or this suite itself) are checked with ``make -n``."""

CHECKOUT_DATA = ("configs", "models")
"""The checkout's folders a command may read without naming them (a training config's ``init_from: models/...``)."""

CHEAP = ("plan-paper",)
"""Subcommands that take a few seconds: run by the default suite too, when they read only the checkout's files."""

EXTRAS: dict[str, Callable[[argparse.Namespace], bool]] = {
    "minari": lambda a: a.command == "collect",
    "onnx": lambda a: a.command == "export",
    "ray": lambda a: a.command == "sweep" or getattr(a, "backend", None) == "ray",
    "tensorboard": lambda a: getattr(a, "tensorboard", None) is not None,
    "example_robot_data": lambda a: (
        getattr(a, "robot", None) not in (None, "paper") and Path(a.robot).suffix not in (".yaml", ".yml")
    ),
}
"""The module of an extra, and the commands that need it."""


@dataclasses.dataclass
class Command:
    """One documented command."""

    page: str
    """the page, relative to the checkout (README.md, docs/rl.md)."""
    line: int
    """its (first) line on the page."""
    text: str
    """as written (one logical line; for a command of a loop, the loop's line with the variables expanded)."""
    program: str
    """``quad-uneven`` or ``make``."""
    argv: list[str]
    """its arguments as the shell passes them (a pattern: as written)."""
    pattern: bool = False
    """it holds a placeholder (or its fence does): checked, not run."""
    inline: bool = False
    """an inline code span (not a line of a shell block)."""

    @functools.cached_property
    def mention(self) -> bool:
        """A pattern, or an inline span that lacks a required option (it names an option in the text)."""
        if self.pattern:
            return True
        if not self.inline or self.program != "quad-uneven":
            return False
        try:
            _parse(self.argv)
        except ValueError as err:
            return "arguments are required" in str(err)
        return False

    def __str__(self) -> str:
        return f"{self.page}:{self.line}: {self.text}"


# -------------------------------------------------------------------------------------------------- discovery
def _logical_lines(content: str) -> list[tuple[int, str]]:
    """(index of the first physical line, text) of each line of a shell block, ``\\`` continuations joined."""
    out, start, parts = [], 0, []
    for i, line in enumerate(content.splitlines()):
        if not parts:
            start = i
        if line.rstrip().endswith("\\"):
            parts.append(line.rstrip()[:-1])
            continue
        parts.append(line)
        out.append((start, " ".join(p.strip() for p in parts)))
        parts = []
    if parts:
        out.append((start, " ".join(p.strip() for p in parts)))
    return out


def _words(text: str) -> list[str]:
    """``text`` split as the shell splits words (comments dropped); [] if it does not split (an open quote)."""
    try:
        return shlex.split(text, comments=True)
    except ValueError:
        return []


def _program(words: list[str]) -> str | None:
    return PROGRAMS.get(words[0]) if words else None


def _is_pattern(text: str) -> bool:
    return bool(PLACEHOLDER.search(" ".join(_words(text))))


RECORDER = r"""
__record() { printf '%s\0' "$__line" "$1" "$(($# - 1))" "${@:2}" >> "$__log"; }
quad-uneven() { __record quad-uneven "$@"; }
make() { __record make "$@"; }
"""


def _expand(content: str, kept: list[tuple[int, str]], page: str, first_line: int) -> list[Command]:
    """The commands of a block as bash runs it: ``kept`` (line index, text) are its command and loop lines."""
    lines = [""] * len(content.splitlines())
    for index, text in kept:
        for name, program in PROGRAMS.items():
            if text.startswith(name + " "):
                text = program + text[len(name) :]
        lines[index] = f"__line={index}; {text}" if _program(_words(text)) else text
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "log"
        log.touch()
        script = Path(tmp) / "block.sh"
        script.write_text(RECORDER + "\n".join(lines) + "\n")
        done = subprocess.run(["bash", str(script)], cwd=tmp, env={**os.environ, "__log": str(log)},
                              capture_output=True, text=True, timeout=60)  # fmt: skip
        if done.returncode != 0:
            raise AssertionError(f"{page}:{first_line}: bash cannot run this block: {done.stderr}")
        fields = log.read_bytes().decode().split("\0")[:-1]
    written = dict(kept)
    commands, i = [], 0
    while i < len(fields):
        index, program, n = int(fields[i]), fields[i + 1], int(fields[i + 2])
        argv = fields[i + 3 : i + 3 + n]
        i += 3 + n
        text = written[index] if "$" not in written[index] else f"{written[index]}  (expanded: {shlex.join(argv)})"
        commands.append(Command(page, first_line + index + 1, text, program, argv))
    return commands


def block_commands(content: str, page: str, first_line: int) -> list[Command]:
    """The project's commands of one shell block (``first_line``: the fence's line on the page, 1-based)."""
    kept = []
    for index, text in _logical_lines(content):
        words = _words(text)
        if _program(words) or (words and words[0] in ("for", "do", "done")):
            kept.append((index, text))
    if not any(_program(_words(text)) for _, text in kept):
        return []
    if any(_is_pattern(text) for _, text in kept):
        return [
            Command(page, first_line + index + 1, text, _program(_words(text)), _words(text)[1:], pattern=True)
            for index, text in kept
            if _program(_words(text))
        ]
    return _expand(content, kept, page, first_line)


def page_commands(path: Path) -> list[Command]:
    """Every command of a page, in the page's order."""
    from markdown_it import MarkdownIt

    page = path.relative_to(ROOT).as_posix()
    commands = []
    for tok in MarkdownIt("commonmark").enable("table").parse(path.read_text()):
        if tok.type == "fence" and tok.info.strip().split(" ")[0] in SHELL_LANGUAGES:
            commands += block_commands(tok.content, page, tok.map[0] + 1)
        for child in tok.children or []:
            words = _words(child.content) if child.type == "code_inline" else []
            if _program(words) and len(words) > 2:
                line = tok.map[0] + 1 if tok.map else 0
                pattern = _is_pattern(child.content)
                commands.append(Command(page, line, child.content, _program(words), words[1:], pattern, inline=True))
    return commands


@functools.cache
def all_commands() -> dict[str, list[Command]]:
    """The commands of every page that shows one, by page."""
    found = {}
    for path in PAGES:
        commands = page_commands(path)
        if commands:
            found[path.relative_to(ROOT).as_posix()] = commands
    return found


def _pages() -> list[str]:
    if importlib.util.find_spec("markdown_it") is None:
        return []
    return list(all_commands())


# ------------------------------------------------------------------------------------------------- the checks
def _parse(argv: list[str]) -> argparse.Namespace:
    """``argv`` parsed by the real parser (paths as written); :raises ValueError: if the parser refuses it."""
    from agents.cli import build_parser

    try:
        return build_parser().parse_args(argv)
    except SystemExit as exc:  # --help or --version
        raise ValueError(f"the parser exits ({exc.code})") from None


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    from agents.cli import build_parser

    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def shorter(argv: list[str]) -> list[str]:
    """``argv`` with the substitutions of :data:`SHORTER` for its subcommand."""
    argv = list(argv)
    for option, value in SHORTER.get(argv[0] if argv else "", {}).items():
        if option in argv:
            argv[argv.index(option) + 1] = value
        else:
            argv += [option, value]
    return argv


def paths(args: argparse.Namespace, outputs: bool) -> list[Path]:
    """The paths ``args`` reads (``outputs`` False) or writes (True), as given."""
    from agents.cli import NAME_OR_PATH

    found = []
    for dest, value in vars(args).items():
        if (dest in OUTPUT_OPTIONS) != outputs:
            continue
        for v in value if isinstance(value, list) else [value]:
            if isinstance(v, Path) or (isinstance(v, str) and dest in NAME_OR_PATH and NAME_OR_PATH[dest](v)):
                found.append(Path(v))
    return found


@functools.cache
def checkout_files() -> frozenset[str]:
    """The checkout's files and folders (relative POSIX paths): git's tracked files, else every file."""
    try:
        listed = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
        files = listed.splitlines()
    except (OSError, subprocess.CalledProcessError):
        files = [p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*") if p.is_file()]
    found = set(files)
    for f in files:
        found.update(p.as_posix() for p in Path(f).parents if p != Path("."))
    return frozenset(found)


def _under(path: Path, folders: list[Path]) -> bool:
    return any(path == f or f in path.parents for f in folders)


def _installed(module: str) -> bool:
    """Whether the extra of ``module`` is installed; example-robot-data ships data, not an importable module."""
    if module == "example_robot_data":
        try:
            importlib.metadata.distribution("example-robot-data")
        except importlib.metadata.PackageNotFoundError:
            return False
        return True
    return importlib.util.find_spec(module) is not None


def _why_not_run(cmd: Command, args: argparse.Namespace, skipped_outputs: list[Path]) -> str | None:
    reason = next((why for why, applies in NOT_RUN.items() if applies(args)), None)
    missing = [m for m, needs in EXTRAS.items() if needs(args) and not _installed(m)]
    if reason is None and missing:
        reason = f"the extra of {missing} is not installed"
    if reason is None and any(_under(p, skipped_outputs) for p in paths(args, outputs=False)):
        reason = "it reads what a command that was not run writes"
    return reason


def check(cmd: Command, produced: list[Path]) -> list[str]:
    """What is wrong with ``cmd`` (one line each); records the paths it writes in ``produced``."""
    if cmd.program == "make":
        return _check_make(cmd)
    subcommands = _subparsers()
    placeholder = cmd.pattern and bool(cmd.argv) and PLACEHOLDER.fullmatch(cmd.argv[0]) is not None
    if not placeholder and (not cmd.argv or cmd.argv[0] not in subcommands):
        return [f"{cmd}: no subcommand {cmd.argv[:1]} (quad-uneven has {sorted(subcommands)})"]
    if cmd.mention:
        named = subcommands.values() if placeholder else [subcommands[cmd.argv[0]]]
        options = set.intersection(*(set(p._option_string_actions) for p in named))
        unknown = [w for w in cmd.argv if w.startswith("--") and w.split("=")[0] not in options]
        return [f"{cmd}: quad-uneven {cmd.argv[0]} has no option {unknown}"] if unknown else []
    problems = []
    try:
        args = _parse(cmd.argv)
        _parse(shorter(cmd.argv))
    except ValueError as err:
        return [f"{cmd}: {err}"]
    for path in paths(args, outputs=False):
        if not (path.is_absolute() or path.as_posix() in checkout_files() or _under(path, produced)):
            problems.append(f"{cmd}: reads {str(path)!r}, which is neither in the checkout nor written before it")
    produced += [p for p in paths(args, outputs=True) if not p.is_absolute()]
    return problems


def _check_make(cmd: Command) -> list[str]:
    if shutil.which("make") is None:
        return []
    done = subprocess.run(["make", "-n", "-C", str(ROOT), *cmd.argv], capture_output=True, text=True, timeout=60)
    return [] if done.returncode == 0 else [f"{cmd}: make -n fails: {done.stderr.strip()[-300:]}"]


@pytest.mark.parametrize("page", _pages())
def test_every_documented_command_parses_and_reads_what_exists(page):
    """The default suite's check of a page: see the module docstring."""
    produced: list[Path] = []
    problems = [p for cmd in all_commands()[page] for p in check(cmd, produced)]
    assert problems == [], "\n".join(problems)


# ---------------------------------------------------------------------------------------------------- the runs
def _workdir(tmp: Path, commands: list[Command]) -> None:
    """Copy into ``tmp`` the checkout's data and the top-level folders and files that ``commands`` read."""
    tops = set(CHECKOUT_DATA)
    for cmd in commands:
        if cmd.program == "quad-uneven" and not cmd.mention:
            for p in paths(_parse(cmd.argv), outputs=False):
                if not p.is_absolute() and p.as_posix() in checkout_files():
                    tops.add(p.parts[0])
    for top in sorted(tops):
        src = ROOT / top
        shutil.copytree(src, tmp / top) if src.is_dir() else shutil.copy2(src, tmp / top)


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def _run_make(cmd: Command, tmp: Path) -> subprocess.CompletedProcess:
    overrides = [f"{k}={tmp / v}" for k, v in (x.split("=", 1) for x in MAKE_RUN[cmd.argv[0]])]
    argv = ["make", "-C", str(ROOT), "-o", ".venv/.installed", *cmd.argv, f"PY={sys.executable}", *overrides]
    return subprocess.run(argv, cwd=tmp, env=_env(), capture_output=True, text=True, timeout=3600)


def run_commands(commands: list[Command], tmp: Path, only: Callable[[Command, argparse.Namespace], bool]) -> int:
    """Run ``commands`` in order in ``tmp`` (those ``only`` accepts); :return: how many ran.

    :raises AssertionError: naming the first command that did not exit 0, with its stderr.
    """
    _workdir(tmp, commands)
    ran, seen, skipped, not_run = 0, set(), [], []
    for cmd in commands:
        if cmd.mention or tuple([cmd.program, *cmd.argv]) in seen:
            continue
        seen.add(tuple([cmd.program, *cmd.argv]))
        if cmd.program == "make":
            first = next(page for page, cmds in all_commands().items() if any(c.argv == cmd.argv for c in cmds))
            if cmd.argv[0] in MAKE_RUN and first == cmd.page and only(cmd, argparse.Namespace(command="make")):
                done = _run_make(cmd, tmp)
                assert done.returncode == 0, f"{cmd}\n{done.stderr[-3000:]}"
                ran += 1
            continue
        args = _parse(cmd.argv)
        reason = _why_not_run(cmd, args, skipped)
        if reason is not None or not only(cmd, args):
            skipped += [p for p in paths(args, outputs=True) if not p.is_absolute()]
            not_run += [f"{cmd} ({reason})"] if reason else []
            continue
        argv = shorter(cmd.argv)
        done = subprocess.run([sys.executable, "-m", "agents.cli", *argv], cwd=tmp, env=_env(), capture_output=True,
                              text=True, timeout=3600)  # fmt: skip
        assert done.returncode == 0, f"{cmd}\nran: quad-uneven {shlex.join(argv)}\n{done.stderr[-3000:]}"
        ran += 1
    if not_run:
        warnings.warn("not run: " + "; ".join(not_run), stacklevel=1)
    return ran


@pytest.mark.slow
@pytest.mark.parametrize("page", _pages())
def test_every_documented_command_runs_as_written(page, tmp_path):
    """make test-slow: the page's commands in order in a fresh folder, shortened by SHORTER only."""
    run_commands(all_commands()[page], tmp_path, lambda cmd, args: True)


def test_the_cheap_documented_commands_run(tmp_path):
    """The commands of :data:`CHEAP` that read only the checkout's files, each in a fresh folder."""
    pytest.importorskip("markdown_it", reason="markdown-it-py is in the dev extra (make installs it)")
    cheap = [c for cmds in all_commands().values() for c in cmds
             if c.program == "quad-uneven" and not c.mention and c.argv[0] in CHEAP]  # fmt: skip
    assert cheap, f"no documented command of {CHEAP}"
    for i, cmd in enumerate(cheap):
        (tmp_path / str(i)).mkdir()
        assert run_commands([cmd], tmp_path / str(i), lambda c, a: True) == 1


# ------------------------------------------------------------------------------------------ the extractor itself
def test_the_extractor_reads_commands_as_the_shell_does(tmp_path):
    """Continuations joined, loops and substitutions expanded, other programs left out, patterns recognised."""
    pytest.importorskip("markdown_it", reason="markdown-it-py is in the dev extra (make installs it)")
    page = ROOT / "docs" / "_extractor_probe.md"
    text = "\n".join([
        "# Probe", "", "```bash",
        "pip install .   # not ours",
        ".venv/bin/quad-uneven evaluate --policy expert --suite smoke \\",
        "    --out 'out/a b'   # a comment",
        "for m in models/distilled runs/x; do",
        "  quad-uneven export --policy $m/model.zip --out $(basename $m).onnx",
        "done",
        "make demo",
        "```", "",
        "Run `quad-uneven compare --baseline a --candidate b --out c` or `quad-uneven train`.", "",
        "```bash",
        "quad-uneven evaluate --policy expert --suite robust --seed K --out runs/rx_K",
        "quad-uneven compare --baseline runs/rx_{1,2} --candidate runs/rx_{3,4} --out runs/c",
        "```", "",
    ])  # fmt: skip
    page.write_text(text)
    try:
        found = page_commands(page)
    finally:
        page.unlink()
    assert [(c.line, c.program, c.argv, c.pattern) for c in found] == [
        (5, "quad-uneven", ["evaluate", "--policy", "expert", "--suite", "smoke", "--out", "out/a b"], False),
        (8, "quad-uneven", ["export", "--policy", "models/distilled/model.zip", "--out", "distilled.onnx"], False),
        (8, "quad-uneven", ["export", "--policy", "runs/x/model.zip", "--out", "x.onnx"], False),
        (10, "make", ["demo"], False),
        (13, "quad-uneven", ["compare", "--baseline", "a", "--candidate", "b", "--out", "c"], False),
        (16, "quad-uneven", ["evaluate", "--policy", "expert", "--suite", "robust", "--seed", "K", "--out",
                             "runs/rx_K"], True),
        (17, "quad-uneven", ["compare", "--baseline", "runs/rx_{1,2}", "--candidate", "runs/rx_{3,4}", "--out",
                             "runs/c"], True),
    ]  # fmt: skip
    produced: list[Path] = []
    assert check(found[2], produced) == [
        f"{found[2]}: reads 'runs/x/model.zip', which is neither in the checkout nor written before it"
    ]
    assert check(found[5], []) == []
    bad = dataclasses.replace(found[5], argv=[*found[5].argv, "--sede", "1"])
    assert check(bad, []) == [f"{bad}: quad-uneven evaluate has no option ['--sede']"]
    bogus = dataclasses.replace(found[0], argv=["plan-paper", "--out", "p", "--bogus"])
    assert "unrecognized arguments: --bogus" in check(bogus, [])[0]
    assert check(dataclasses.replace(found[3], argv=["no-such-target"]), [])[0].endswith(
        "No rule to make target 'no-such-target'.  Stop."
    )


def test_every_page_with_commands_is_found():
    """The pages that show the quick start and the trainings are among those checked (discovery did not go blind)."""
    pytest.importorskip("markdown_it", reason="markdown-it-py is in the dev extra (make installs it)")
    found = all_commands()
    assert {"README.md", "docs/rl.md", "docs/evaluation.md", "docs/paper.md"} <= set(found)
    readme = [c.argv for c in found["README.md"]]
    assert ["demo"] in readme and any(a[:1] == ["train"] for a in readme)
