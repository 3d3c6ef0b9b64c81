"""README.md's code blocks run, the docs' commands parse, and every link resolves.

After vector-quantize-pytorch's ``tests/test_readme.py``: each ```python block of the
README runs in a fresh namespace in a shared temporary working directory (blocks in
README order, so a later block may read a file an earlier one wrote); a block that
defines ``test_*`` functions (the pytest plugin's) runs as a test file, once recording
its goldens and once checking them. Each ```bash block's ``habitsim`` commands are parsed
by the command line's own parser (the subcommand and every option exist), ``make``
targets are looked up in the Makefile, and blocks of quick commands are run with the
installed command. The ``habitsim`` commands in ``docs/*.md`` are parsed the same way and
their ```python blocks compiled, and ``docs/cli.md`` must name every command and option of
the command line. The working directory holds ``habitsim/examples`` and ``tests/robots``
of this checkout, the paths the README's commands name.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
PAGES = [README, ROOT / "CHANGELOG.md", *DOCS]

#: Commands too long to run here (half a minute to hours): only parsed.
LONG = {"eval", "bench", "train", "train-evaluator", "demo", "refine", ("data", "synth")}
#: Calls that make a Python block slow (IPOPT solves, MuJoCo rollouts, the model's first
#: load): ``make test-fast`` leaves those blocks out.
SLOW_CALLS = ("transfer(", "refine(", "track(", "run_clip(", "track_clip(", "habitsim_track")

_FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)
_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _blocks(path: Path, lang: str) -> list[str]:
    return [m.group(2) for m in _FENCE.finditer(path.read_text()) if m.group(1) == lang]


def _commands(block: str) -> list[list[str]]:
    """The block's command lines as argument lists (continuations joined, comments cut)."""
    out = []
    for line in block.replace("\\\n", " ").splitlines():
        args = shlex.split(line, comments=True)
        if args:
            out.append(args)
    return out


def _is_long(args: list[str]) -> bool:
    return args[0] != "habitsim" or args[1] in LONG or tuple(args[1:3]) in LONG


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("readme")
    for part in ("habitsim/examples", "tests/robots"):
        (d / part).parent.mkdir(parents=True, exist_ok=True)
        (d / part).symlink_to(ROOT / part, target_is_directory=True)
    return d


def _readme_blocks() -> list:
    params = []
    for i, m in enumerate(_FENCE.finditer(README.read_text())):
        lang, code = m.group(1), m.group(2)
        if lang not in ("python", "bash"):
            continue
        slow = (lang == "bash" and not any(_is_long(a) for a in _commands(code))) or (
            lang == "python" and any(c in code for c in SLOW_CALLS)
        )
        marks = [pytest.mark.slow] if slow else []
        params.append(pytest.param(lang, code, id=f"{i:02d}-{lang}", marks=marks))
    return params


def _run_python(code: str, workdir: Path, monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    monkeypatch.chdir(workdir)
    exec(compile(code, name, "exec"), {"__name__": "__readme__"})


def _run_plugin_tests(code: str, pytester: pytest.Pytester) -> None:
    n = len(re.findall(r"^def test_", code, re.M))
    pytester.makepyfile(test_readme_plugin=code)
    pytester.runpytest_inprocess(
        "-p", "no:cacheprovider", "--habitsim-update-goldens"
    ).assert_outcomes(passed=n)
    pytester.runpytest_inprocess("-p", "no:cacheprovider").assert_outcomes(passed=n)


def _run_bash(code: str, workdir: Path) -> None:
    exe = Path(sys.executable).with_name("habitsim")
    prog = [str(exe)] if exe.exists() else [sys.executable, "-m", "habitsim"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    for args in _commands(code):
        done = subprocess.run(
            prog + args[1:], cwd=workdir, capture_output=True, text=True, env=env, timeout=300
        )
        assert done.returncode == 0, f"{shlex.join(args)} exited {done.returncode}:\n{done.stderr}"


@pytest.mark.parametrize(("lang", "code"), _readme_blocks())
def test_readme_block(
    lang: str, code: str, workdir: Path, monkeypatch: pytest.MonkeyPatch, request
) -> None:
    """Each README block runs (python) or its commands parse and, when quick, run (bash)."""
    name = f"README.md {request.node.callspec.id}"
    if lang == "python":
        if re.search(r"^def test_", code, re.M):
            _run_plugin_tests(code, request.getfixturevalue("pytester"))
        else:
            _run_python(code, workdir, monkeypatch, name)
        return
    cmds = _commands(code)
    for args in cmds:
        _check_command(args)
    if not any(_is_long(a) for a in cmds):
        _run_bash(code, workdir)


def _check_command(args: list[str]) -> None:
    """A documented command exists: a Makefile target, a pytest option, or a ``habitsim``
    command line the parser accepts."""
    from habitsim.cli import build_parser

    if args[0] == "make":
        targets = re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M)
        assert set(args[1:]) <= set(targets), f"{shlex.join(args)}: no such make target"
    elif args[0] == "pytest":
        assert all(a in ("--habitsim-update-goldens",) for a in args[1:] if a.startswith("-"))
    elif args[0] == "habitsim":
        try:
            build_parser().parse_args(args[1:])
        except SystemExit as e:
            pytest.fail(f"{shlex.join(args)}: the command line rejects it (exit {e.code})")


def _doc_commands() -> list:
    out = []
    for page in DOCS:
        for block in _blocks(page, "bash"):
            for args in _commands(block):
                if args[0] == "habitsim":
                    out.append(pytest.param(args, id=f"{page.name}: {shlex.join(args)[:60]}"))
    return out


@pytest.mark.parametrize("args", _doc_commands())
def test_docs_commands_parse(args: list[str]) -> None:
    """Every ``habitsim`` command in a docs page names a real command and real options."""
    _check_command(args)


@pytest.mark.parametrize("page", DOCS, ids=lambda p: p.name)
def test_docs_python_compiles(page: Path) -> None:
    for i, block in enumerate(_blocks(page, "python")):
        compile(block, f"{page.name} block {i}", "exec")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_links_resolve(page: Path) -> None:
    """Every relative link (and image) of README.md, CHANGELOG.md and docs/*.md is a file."""
    missing = []
    for target in _LINK.findall(page.read_text()):
        if re.match(r"^(https?:|mailto:|#)", target):
            continue
        if not (page.parent / target.split("#")[0]).exists():
            missing.append(target)
    assert not missing, f"{page.name}: links to missing files: {missing}"


#: Commands on their way out, not documented.
UNDOCUMENTED = {"fuzz"}


def _parser_commands(parser, prefix: str = ""):
    """(command path, parser) of every (sub)command of the command line."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                if name in UNDOCUMENTED:
                    continue
                path = f"{prefix} {name}".strip()
                yield path, sub
                yield from _parser_commands(sub, path)


def test_cli_page_covers_every_command_and_option() -> None:
    """docs/cli.md names every command and every one of its options."""
    from habitsim.cli import build_parser

    text = (ROOT / "docs" / "cli.md").read_text()
    missing = []
    for path, sub in _parser_commands(build_parser()):
        head = re.compile(rf"^\| `{re.escape(path)}[ `]")
        rows = " ".join(ln for ln in text.splitlines() if head.match(ln))
        if not rows:
            missing.append(path)
            continue
        for action in sub._actions:
            long = [o for o in action.option_strings if o.startswith("--") and o != "--help"]
            if long and not any(re.search(rf"{re.escape(o)}(?![\w-])", rows) for o in long):
                missing.append(f"{path} {long[0]}")
    assert not missing, f"docs/cli.md does not name: {missing}"


def test_readme_is_a_guide() -> None:
    """The README stays short; neither it nor a docs page mentions a command that is gone
    (the fuzzer is the developer tool ``make fuzz``)."""
    assert README.read_text().count("\n") <= 200
    for page in (README, *DOCS):
        assert "habitsim fuzz" not in page.read_text(), page.name
