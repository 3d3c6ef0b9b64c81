"""The method registry (:mod:`habitsim.transfer_methods`): the source clip's id passed to
methods that take it, and methods of installed packages registered by entry point."""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import pytest
from helpers import EVAL_ARGS, install_plugin

from habitsim.cli import build_parser, main
from habitsim.gaits import generate
from habitsim.transfer_methods import (
    ENTRY_POINT_GROUP,
    METHODS,
    LazyFunction,
    MethodPluginWarning,
    MethodRegistry,
    direct_transfer,
    run_method,
)

PLUGIN_CODE = '''
from habitsim.transfer_methods import direct_transfer

SEEN = []


def plugged(source, target, *, seed=0, clip_id=None, **options):
    """The direct transfer, noting the clip id it was given."""
    SEEN.append(clip_id)
    out = direct_transfer(source, target, seed=seed)
    out.metadata["clip_id"] = clip_id
    return out
'''


@pytest.fixture
def walk():
    return generate("dog", "walk", seed=0, duration_s=0.5)


def test_clip_id_reaches_only_methods_that_take_it(walk) -> None:
    seen: list[str | None] = []

    def takes(source, target, *, seed=0, clip_id=None):
        seen.append(clip_id)
        return direct_transfer(source, target)

    def ignores(source, target, *, seed=0):  # written before clip ids were passed
        return direct_transfer(source, target)

    reg = MethodRegistry()
    takes_m = reg.register("takes", takes)
    ignores_m = reg.register("ignores", ignores)
    run_method(takes_m, walk, "cat", clip_id="dog_walk_0000")
    run_method(takes_m, walk, "cat")
    assert seen == ["dog_walk_0000", None]
    assert run_method(ignores_m, walk, "cat", clip_id="dog_walk_0000").species == "cat"


def test_entry_point_methods_join_the_registry(tmp_path: Path, monkeypatch, walk) -> None:
    install_plugin(tmp_path, "plug_dist", "plug_mod", PLUGIN_CODE, {"plugged": "plug_mod:plugged"})
    monkeypatch.syspath_prepend(str(tmp_path))
    reg = MethodRegistry(ENTRY_POINT_GROUP)
    assert "plugged" in reg and "plugged" in list(reg)
    m = reg["plugged"]
    assert m.kind == "external" and m.fn == LazyFunction("plug_mod", "plugged")
    assert "plug_mod" not in sys.modules  # imported on the first call only
    out = run_method(m, walk, "cat", clip_id="dog_walk_0000")
    assert out.metadata["clip_id"] == "dog_walk_0000"
    assert reg.load_entry_points() == []  # found once
    monkeypatch.delitem(sys.modules, "plug_mod")


def test_a_bad_entry_point_is_left_out_with_a_warning(tmp_path: Path, monkeypatch) -> None:
    entries = {"direct": "plug_bad:plugged", "Bad-Name": "plug_bad:plugged", "ok_one": "plug_bad"}
    install_plugin(tmp_path, "bad_dist", "plug_bad", PLUGIN_CODE, entries)
    monkeypatch.syspath_prepend(str(tmp_path))
    reg = MethodRegistry(ENTRY_POINT_GROUP)
    reg.register("direct", direct_transfer)
    with pytest.warns(MethodPluginWarning) as caught:
        names = list(reg)
    assert names == ["direct"] and len(caught) == 3
    assert reg["direct"].fn is direct_transfer


@pytest.mark.slow
def test_a_plugin_method_is_in_the_eval_table(
    small_dataset: Path, tmp_path: Path, monkeypatch
) -> None:
    """Installed by entry point, no code inside habitsim: listed by ``eval --help`` and
    evaluated, with the source clip's id passed."""
    install_plugin(
        tmp_path / "site", "plug_dist", "plug_eval", PLUGIN_CODE, {"plugged": "plug_eval:plugged"}
    )
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    monkeypatch.setattr(METHODS, "_methods", dict(METHODS._methods))
    monkeypatch.setattr(METHODS, "_plugins_loaded", False)
    sub = build_parser()._subparsers._group_actions[0].choices["eval"]
    assert "plugged" in sub.format_help()
    out = tmp_path / "run"
    args = [a if a != "direct" else "direct,plugged" for a in EVAL_ARGS]
    assert main(["eval", "--data", str(small_dataset), "--out", str(out), *args]) == 0
    with open(out / "rows.csv") as fh:
        rows = list(csv.DictReader(fh))
    plugged = [r for r in rows if r["method"] == "plugged"]
    assert plugged and all(r["status"] == "ok" for r in plugged)
    assert "plugged" in (out / "summary.md").read_text()
    clip_ids = {Path(r["clip"]).stem for r in plugged}
    assert set(sys.modules["plug_eval"].SEEN) == clip_ids
    monkeypatch.delitem(sys.modules, "plug_eval")
