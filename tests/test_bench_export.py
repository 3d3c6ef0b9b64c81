"""``habitsim bench export``: a motion onto a rig and back, per rig."""

from __future__ import annotations

import json

from foreign_rig import _foreign_rig

import habitsim
from habitsim.cli import main
from habitsim.evaluation.bench.export import OWN, export_checks, run_export


def test_bench_export_on_a_test_rig(tmp_path, capsys):
    rig = tmp_path / "rig.bvh"
    rig.write_text(_foreign_rig(habitsim.generate("dog", "walk", seed=3, duration_s=1.5)).to_text())
    res = run_export([rig], duration_s=1.5, own_seconds=None)
    assert [c.motion for c in res.cases] == ["walk", "trot", OWN]
    own = res.cases[-1]
    assert own.figures["max_mm"] <= 1.0 and own.joints == 30
    own_check, synthetic = export_checks(res)
    assert own_check.verdict == "met" and own_check.value == own.figures["max_mm"]
    # a motion other than the rig's own clip comes back too: the root's scale and height
    # are one rule both ways (the legs' ratio, the body on its stance toes)
    worst = max(c.figures["max_mm"] for c in res.cases[:2])
    assert synthetic.verdict == "met" and synthetic.value == worst
    code = main(["bench", "export", str(rig), "--duration", "1.5", "--json", "--check"])
    assert code == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line[:1] == "{"]
    assert {r["motion"] for r in rows} == {"walk", "trot", OWN}
