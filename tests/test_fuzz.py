"""Hypothesis-driven fuzzing of the readers and the command line: every input is either
read or refused with a :class:`~habitsim.errors.HabitsimError`, never another exception.
The mutations are those of the developer tool ``tests/fuzzing`` (whose long campaign is
``make fuzz``), driven here by hypothesis with a small number of examples so the file
runs in seconds, and a short campaign through the tool's command line."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import pytest
from fuzzing import campaign as fuzz
from fuzzing.__main__ import main as fuzz_main
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from habitsim.bvh import parse_bvh
from habitsim.errors import HabitsimError

FAST = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@pytest.fixture(scope="module")
def ws():
    with fuzz.Workspace() as w:
        yield w


def _check(ws: fuzz.Workspace, case: fuzz.Case) -> None:
    outcome, exc = fuzz.run_case(ws, case)
    if outcome == "raw":
        raise AssertionError(f"raw {type(exc).__name__} on {case.target}: {exc}") from exc


@pytest.mark.slow
@pytest.mark.parametrize("target", ["bvh", "npz", "species", "manifest"])
def test_mutated_inputs_are_read_or_refused(ws, target: str) -> None:
    @FAST
    @given(rnd=st.randoms(use_true_random=False))
    def check(rnd) -> None:
        _check(ws, fuzz.make_case(target, ws, rnd))

    check()


@pytest.mark.slow
def test_mutated_bvh_imports_are_read_or_refused(ws) -> None:
    @settings(FAST, max_examples=10)
    @given(rnd=st.randoms(use_true_random=False))
    def check(rnd) -> None:
        _check(ws, fuzz.make_case("bvh_import", ws, rnd))

    check()


@pytest.mark.slow
def test_cli_entry_points(ws) -> None:
    @settings(FAST, max_examples=15)
    @given(rnd=st.randoms(use_true_random=False))
    def check(rnd) -> None:
        _check(ws, fuzz.make_case("cli", ws, rnd))

    check()


@pytest.mark.slow
@FAST
@given(text=st.text(max_size=3000))
def test_arbitrary_text_as_bvh(text: str) -> None:
    try:
        parse_bvh(text)
    except HabitsimError:
        pass


_BVH_TOKENS = st.sampled_from(
    [
        "HIERARCHY",
        "ROOT",
        "JOINT",
        "End",
        "Site",
        "{",
        "}",
        "OFFSET",
        "CHANNELS",
        "MOTION",
        "Frames:",
        "Frame",
        "Time:",
        "3",
        "6",
        "0",
        "1",
        "-1",
        "1e-320",
        "1e300",
        "nan",
        "Xrotation",
        "Yrotation",
        "Zrotation",
        "Xposition",
        "a",
        "\n",
    ]
)


@FAST
@given(tokens=st.lists(_BVH_TOKENS, max_size=200))
def test_bvh_token_soup(tokens: list[str]) -> None:
    try:
        parse_bvh(" ".join(tokens))
    except HabitsimError:
        pass


@FAST
@given(raw=st.binary(max_size=3000))
def test_arbitrary_bytes_as_npz(raw: bytes) -> None:
    from habitsim.motion import load_motion

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "m.npz"
        p.write_bytes(raw)
        with pytest.raises(HabitsimError):
            load_motion(p)


@FAST
@given(text=st.text(max_size=2000))
def test_arbitrary_text_as_species_toml(text: str) -> None:
    from habitsim.species import load_species_file

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "x.toml"
        p.write_text(text, encoding="utf-8", errors="surrogatepass")
        with pytest.raises(HabitsimError):
            load_species_file(p)


@pytest.mark.slow
@pytest.mark.parametrize("target", ["t2m", "fromclip", "score", "methods", "rig", "loop"])
def test_newer_inputs_are_read_or_refused(ws, target: str) -> None:
    """The families of the newer inputs (:mod:`fuzzing.wave`): text prompts, species from
    a clip, score folders, entry-point methods in eval, export onto a rig, loops."""

    @settings(FAST, max_examples=4)
    @given(rnd=st.randoms(use_true_random=False))
    def check(rnd) -> None:
        _check(ws, fuzz.make_case(target, ws, rnd))

    check()


def test_campaign_counts() -> None:
    res = fuzz.campaign(30, seed=3, targets=["bvh", "species"])
    assert sum(res.total.values()) == 30 and res.total["raw"] == 0
    assert "total" in res.table()


# ---------------------------------------------------------------------- python -m fuzzing


def test_fuzz_tool_prints_counts_by_outcome(capsys) -> None:
    code = fuzz_main(["--n", "12", "--targets", "bvh,species", "--no-progress", "--check"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "fuzz: 12 inputs, seed 0" in out and "target: 0 raw tracebacks" in out
    header = next(ln for ln in out.splitlines() if ln.startswith("target "))
    assert header.split() == [
        "target",
        "inputs",
        "ok",
        "typed",
        "raw",
        "hang",
        "memory",
        "peak",
        "MB",
    ]
    total = next(ln for ln in out.splitlines() if ln.startswith("total"))
    assert total.split()[1] == "12" and total.split()[4:7] == ["0", "0", "0"]


def test_fuzz_tool_check_exit_code(monkeypatch, capsys) -> None:
    """A raw exception is shown with its input; only --check turns it into exit code 1."""

    def broken(ws, case):
        raise RuntimeError("a raw bug")

    monkeypatch.setitem(fuzz._RUNNERS, "species", broken)
    argv = ["--n", "3", "--targets", "species", "--no-progress"]
    assert fuzz_main(argv) == 0
    out = capsys.readouterr().out
    assert "raw RuntimeError on a species input" in out and "MISSED" in out
    assert fuzz_main([*argv, "--check"]) == 1


@pytest.mark.parametrize(
    "argv", [["--n", "0"], ["--n", "10000000"], ["--show", "-1"], ["--seed", "-1"]]
)
def test_fuzz_tool_bounds(capsys, argv: list[str]) -> None:
    assert fuzz_main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "valid" in err


def test_fuzz_is_not_in_the_package() -> None:
    import importlib.util

    from habitsim.cli import build_parser

    assert importlib.util.find_spec("habitsim.fuzz") is None
    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert "fuzz" not in commands.choices


@pytest.mark.slow
def test_heavy_commands_on_absurd_motions(ws) -> None:
    """transfer / refine / track / eval on valid-shaped but absurd motions (fps at the
    ends of its range, one frame, roots far away or under the floor, random rotations)."""

    @settings(FAST, max_examples=8)
    @given(rnd=st.randoms(use_true_random=False))
    def check(rnd) -> None:
        _check(ws, fuzz.make_case("heavy", ws, rnd))

    check()


def test_absurd_motions_are_valid_motions() -> None:
    import random

    for seed in range(40):
        m, note = fuzz._absurd_motion(random.Random(seed))
        assert 1 <= m.num_frames and m.duration <= fuzz.HEAVY_MAX_SECONDS + 1.0 / m.fps, note
