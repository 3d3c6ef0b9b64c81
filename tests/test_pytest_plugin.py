"""The pytest plugin's fixtures are documented: a docstring each (``pytest --fixtures``),
and named in the README's plugin section and in docs/testing.md."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

from habitsim import pytest_plugin

ROOT = Path(__file__).resolve().parents[1]


def _fixtures() -> dict[str, str | None]:
    """Fixture name → docstring, read from the plugin's source."""
    tree = ast.parse(inspect.getsource(pytest_plugin))
    out = {}
    for node in tree.body:
        if not isinstance(node, ast.FunctionDef):
            continue
        for dec in node.decorator_list:
            target = dec.func if isinstance(dec, ast.Call) else dec
            if ast.unparse(target) == "pytest.fixture":
                out[node.name] = ast.get_docstring(node)
    return out


def test_the_plugin_has_its_five_fixtures() -> None:
    assert set(_fixtures()) == {
        "habitsim_clip",
        "habitsim_species_model",
        "habitsim_track",
        "habitsim_golden",
        "habitsim_assert_plausible",
    }


@pytest.mark.parametrize("name", sorted(_fixtures()))
def test_every_fixture_has_a_docstring(name: str) -> None:
    doc = _fixtures()[name]
    assert doc and doc.startswith("habitsim: "), f"{name} needs a docstring for pytest --fixtures"


@pytest.mark.parametrize("page", ["README.md", "docs/testing.md"])
def test_every_fixture_is_named_in_the_docs(page: str) -> None:
    text = (ROOT / page).read_text()
    if page == "README.md":
        start = text.index("## Physics regression checks in your own suite")
        text = text[start : text.index("\n## ", start + 1)]
    missing = [name for name in _fixtures() if f"`{name}`" not in text]
    assert not missing, f"{page} does not name {missing}"
