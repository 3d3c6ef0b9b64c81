"""The package configuration ships every data file without setuptools warnings."""

from __future__ import annotations

import importlib.util
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _setup_packages() -> list[str]:
    spec = importlib.util.spec_from_file_location("habitsim_setup", ROOT / "setup.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # not __main__: defines packages() without building
    return mod.packages()


def test_every_shipped_data_folder_is_a_package() -> None:
    """setuptools warns once per file of a data folder missing from ``packages``."""
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]
    assert "packages" not in cfg["setuptools"], "packages come from setup.py"
    dirs = {v: k for k, v in cfg["setuptools"]["package-dir"].items()}
    packages = set(_setup_packages())
    for folder, name in dirs.items():
        for data in (ROOT / folder).rglob("*"):
            if not data.is_file() or "__pycache__" in data.parts or data.suffix == ".pyc":
                continue
            rel = data.parent.relative_to(ROOT / folder)
            if any(not p.isidentifier() for p in rel.parts):
                continue  # e.g. a build's temporary ".cat.tmp" folder: not shipped
            pkg = ".".join((name, *rel.parts))
            assert pkg in packages, f"{data.relative_to(ROOT)}: {pkg} missing from packages"
    for needed in (
        "habitsim.mjcf_models.cat",
        "habitsim.mjcf_models.cat.assets",
        "habitsim.evaluation.evaluator",
        "habitsim.models.checkpoints.habit",
    ):
        assert needed in packages
