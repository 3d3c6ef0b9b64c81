"""Architecture facts: a light core, one name per module, one controller registry."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Source folders installed under ``habitsim.``: never imported by their bare names (from
#: the repository root both would import, as two different modules).
BARE = ("controllers", "evaluation", "mjcf_models")


def test_core_imports_without_torch() -> None:
    code = (
        "import sys\n"
        "import habitsim, habitsim.controllers, habitsim.bvh, habitsim.sim\n"
        "print(sorted(m for m in ('torch', 'roma') if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT / "tests"
    )
    assert out.stdout.strip() == "[]"


def test_refine_attribute_is_the_module() -> None:
    code = (
        "import types, habitsim\n"
        "first, second = habitsim.refine, habitsim.refine\n"
        "import habitsim.refine\n"
        "from habitsim.refine import refine\n"
        "assert isinstance(first, types.ModuleType) and first is second is habitsim.refine\n"
        "assert callable(refine) and first.refine is refine\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT / "tests")


def _python_files() -> list[Path]:
    out: list[Path] = []
    for folder in ("habitsim", *BARE, "tests"):
        out += sorted(p for p in (ROOT / folder).rglob("*.py") if "__pycache__" not in p.parts)
    out += [p for p in (ROOT / "setup.py",) if p.exists()]
    return out


def test_no_bare_top_level_imports() -> None:
    bad = []
    for path in _python_files():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            elif (
                isinstance(node, ast.Call)
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str)
                and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module"
            ):
                names = [node.args[0].value]
            for n in names:
                if n.split(".")[0] in BARE:
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {n}")
    assert not bad, "import these as habitsim.<name>:\n" + "\n".join(bad)


def test_one_controller_registry() -> None:
    import habitsim.controllers as C
    import habitsim.sim as S
    from habitsim.cli import track_cmd

    assert S.CONTROLLERS is C.CONTROLLERS is C.CONTROLLER_NAMES
    assert set(C.CONTROLLERS) == set(C.REGISTRY)
    assert {"servo", "pd", "balance", "mpc"} <= set(C.CONTROLLERS)
    assert track_cmd is not None


def test_command_selections_come_from_the_registry() -> None:
    """Benchmarks and commands that offer a subset of the controllers offer registry names."""
    from habitsim.cli import bench_balance, bench_refine, retarget_cmd
    from habitsim.controllers import CONTROLLERS, REGISTRY

    torque = {n for n, s in REGISTRY.items() if s.actuators == "torque"}
    assert set(bench_balance.CONTROLLERS) == set(retarget_cmd.TRACK_CONTROLLERS) == torque
    assert set(bench_refine._SURVIVAL_CONTROLLERS) <= set(CONTROLLERS)


@pytest.mark.parametrize("name", ["servo", "servo+id+stance", "pd"])
def test_registry_builds_every_kind(name: str) -> None:
    from habitsim.controllers import Controller, make_controller
    from habitsim.sim import servo_model, species_model

    base = species_model("dog")
    model = servo_model(base) if name.startswith("servo") else base
    ctl = make_controller(name, model)
    assert isinstance(ctl, Controller)
