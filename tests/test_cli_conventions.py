"""CLI conventions: a closed pipe, one list syntax, --check exit codes, legends."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from habitsim.cli import EXIT_CLOSED_PIPE, build_parser, main
from habitsim.cli.conventions import ListAction, check_exit, split_names

#: Options that take ONE species (the skeleton a BVH is imported onto or sized against).
_SINGLE = {
    ("bench real", "--species"),
    ("bench inplace", "--species"),
    ("bench export", "--species"),
    ("bench render", "--species"),
    ("bench variants", "--species"),
    ("data import-bvh", "--species"),
    ("data inspect-bvh", "--species"),
    # the one skeleton a motion-capture source is imported onto (also --from)
    ("transfer", "--species"),
    ("retarget", "--species"),
    # the one species the scored files must be
    ("score", "--species"),
    # the one species a generated clip is of (when the prompt names none)
    ("t2m generate", "--species"),
}
_LIST_FLAGS = ("--species", "--targets", "--sources", "--methods")


def _commands(parser: argparse.ArgumentParser, prefix: str = ""):
    """(command path, parser) of every (sub)command."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                path = f"{prefix} {name}".strip()
                yield path, sub
                yield from _commands(sub, path)


@pytest.mark.slow
def test_closed_pipe_exits_quietly() -> None:
    """``habitsim species list | head -1``: no BrokenPipeError traceback."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "habitsim", "species", "list"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()  # the reader goes away before the command writes a byte
    err = proc.stderr.read().decode()
    proc.stderr.close()
    code = proc.wait(timeout=120)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert code == EXIT_CLOSED_PIPE


@pytest.mark.slow
def test_open_pipe_still_prints_everything() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "habitsim", "species", "list"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert done.stdout.count("\n") >= 18 and not done.stderr


def test_every_list_option_takes_both_syntaxes() -> None:
    parser = build_parser()
    seen = set()
    for path, sub in _commands(parser):
        for action in sub._actions:
            for flag in action.option_strings:
                if flag in _LIST_FLAGS and (path, flag) not in _SINGLE:
                    assert isinstance(action, ListAction), f"habitsim {path} {flag}"
                    seen.add((path, flag))
    for needed in [
        ("bench sim", "--species"),
        ("bench refine", "--species"),
        ("bench balance", "--species"),
        ("bench real", "--targets"),
        ("models build", "--species"),
        ("data synth", "--species"),
        ("demo", "--targets"),
        ("eval", "--sources"),
        ("eval", "--targets"),
    ]:
        assert needed in seen, needed


@pytest.mark.parametrize(
    "argv",
    [
        ["bench", "refine", "--species", "{}"],
        ["bench", "balance", "--species", "{}"],
        ["models", "build", "--species", "{}"],
        ["data", "synth", "--out", "x", "--species", "{}"],
        ["demo", "--targets", "{}"],
        ["eval", "--out", "x", "--targets", "{}"],
        ["bench", "real", "--data", "x", "--targets", "{}"],
    ],
)
def test_comma_and_space_give_the_same_list(argv: list[str]) -> None:
    parser = build_parser()
    i = argv.index("{}")
    results = []
    for names in (
        ["cat,dog,horse"],
        ["cat", "dog", "horse"],
        ["cat,dog", "horse"],
        ["cat, dog", "horse,"],
    ):
        ns = parser.parse_args(argv[:i] + names + argv[i + 1 :])
        results.append(getattr(ns, argv[i - 1].lstrip("-")))
    assert all(r == ["cat", "dog", "horse"] for r in results), results


def test_list_choices_and_conversion_are_checked_after_splitting(capsys) -> None:
    parser = build_parser()
    ns = parser.parse_args(["bench", "refine", "--stages", "A,B", "--lengths", "100,300"])
    assert ns.stages == ["A", "B"] and ns.lengths == [100, 300]
    with pytest.raises(SystemExit) as e:
        parser.parse_args(["bench", "refine", "--stages", "A,C"])
    assert e.value.code == 2 and "'C'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parser.parse_args(["bench", "refine", "--lengths", "100,many"])


def test_split_names() -> None:
    assert split_names(None) == [] and split_names(" ,") == []
    assert split_names("cat, dog,cat") == ["cat", "dog"]
    assert split_names(["cat,dog", "horse"]) == ["cat", "dog", "horse"]


def test_bad_species_in_a_list_is_an_error(capsys) -> None:
    assert main(["models", "build", "--species", "cat", "hores", "--out", "/nonexistent"]) == 2
    assert "hores" in capsys.readouterr().err


def test_every_bench_with_targets_has_check() -> None:
    benches = {path: sub for path, sub in _commands(build_parser()) if path.startswith("bench ")}
    for name in ("data", "sim", "refine", "balance", "train"):
        flags = {f for a in benches[f"bench {name}"]._actions for f in a.option_strings}
        assert "--check" in flags, name


def test_check_exit(capsys) -> None:
    assert check_exit([], True) == 0 and check_exit(["x"], False) == 0
    assert check_exit(["solve 3 s > 2 s"], True) == 1
    assert "solve 3 s > 2 s" in capsys.readouterr().err


def test_bench_check_exits_1_on_a_miss(capsys) -> None:
    """bench sim prints MISSED and, with --check only, exits 1."""
    from habitsim.cli.bench_sim import _bench_sim
    from habitsim.evaluation.bench.sim import SimTargets

    def run(args: list[str], targets: SimTargets) -> int:
        return _bench_sim(build_parser().parse_args(args), targets)

    unreachable = SimTargets(batch_ratio=1e9)
    argv = [
        "bench",
        "sim",
        "--species",
        "cat",
        "--skip-quality",
        "--duration",
        "0.2",
        "--batch",
        "1",
        "--repeats",
        "1",
        "--threads",
        "1",
    ]
    assert run(argv, unreachable) == 0
    out = capsys.readouterr().out
    assert "MISSED" in out and "b/raw: batch/s ÷ raw/s" in out.replace("\n", " ")
    assert run([*argv, "--check"], unreachable) == 1
    assert run([*argv, "--check"], SimTargets(batch_ratio=0.0)) == 0  # always met


def test_balance_missed_targets() -> None:
    from habitsim.evaluation.bench.balance import missed_targets

    good = {
        "stance_qp_median_ms": 0.1,
        "mpc_median_ms": 1.0,
        "realtime_factor_mpc": 9.0,
        "survival_share_mpc": 1.0,
        "mpjpe_per_leg_mpc": 0.05,
    }
    assert missed_targets(good, ["pd", "balance", "mpc"]) == []
    slow = {**good, "mpc_median_ms": 7.0, "survival_share_mpc": float("nan")}
    assert len(missed_targets(slow, ["mpc"])) == 2
    assert missed_targets({"stance_qp_median_ms": float("nan")}, ["pd"]) == []
