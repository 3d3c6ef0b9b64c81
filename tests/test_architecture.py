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


@pytest.mark.slow
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


@pytest.mark.slow
def test_cli_parser_without_torch() -> None:
    """``habitsim --help`` builds every command's parser without the learning core."""
    code = (
        "import sys, contextlib, io\n"
        "import habitsim.cli\n"
        "habitsim.cli.build_parser()\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    habitsim.cli.main(['--help'])\n"
        "print(sorted(m for m in ('torch', 'roma') if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT / "tests"
    )
    assert out.stdout.strip() == "[]"


@pytest.mark.slow
def test_models_names_stay_the_functions() -> None:
    """The learning core loads on first use; ``habitsim.models.transfer`` / ``.train`` stay
    the functions even when their submodules are imported first."""
    code = (
        "import sys, types\n"
        "import habitsim.models.config\n"
        "assert 'torch' not in sys.modules\n"
        "import habitsim.models.transfer, habitsim.models.train\n"
        "import habitsim.models as M\n"
        "from habitsim.models import transfer, train, METHODS\n"
        "assert isinstance(transfer, types.FunctionType) and M.transfer is transfer\n"
        "assert isinstance(train, types.FunctionType) and M.train is train\n"
        "assert sys.modules['habitsim.models.transfer'].transfer is transfer and METHODS\n"
        "import habitsim\n"
        "assert habitsim.transfer is transfer\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT / "tests")


@pytest.mark.slow
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
    assert all(callable(spec.build) for spec in C.REGISTRY.values())  # make_controller calls it
    assert {"servo", "pd", "balance", "mpc"} <= set(C.CONTROLLERS)
    assert track_cmd is not None


def test_one_method_registry() -> None:
    """One transfer-method registry: the API, the pipeline, the evaluation and the
    command line take every method name from :data:`habitsim.transfer_methods.METHODS`;
    no other module defines a ``METHODS`` or a ``register_method``, and none re-exports
    the registry under a second module name (the benchmark's old
    ``habitsim.evaluation.methods`` is gone)."""
    import habitsim.evaluation as E
    import habitsim.transfer_methods as T
    from habitsim.cli import build_parser
    from habitsim.models.config import VARIANTS

    assert E.register_method is T.register_method and E.get_method is T.get_method
    assert "habitsim.transfer_methods" in import_graph()["habitsim.pipeline"]
    assert [n for n, m in T.METHODS.items() if m.learned] == list(VARIANTS)
    transfer_help = next(
        a.choices["transfer"]
        for a in build_parser()._actions
        if hasattr(a, "choices") and a.choices
    ).description
    assert all(f"{name}:" in transfer_help for name in T.METHODS)
    assert not (ROOT / "evaluation" / "methods.py").exists()
    defined, via = [], []
    for path in _python_files():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef) and node.name in ("register_method", "METHODS"):
                defined.append(str(path.relative_to(ROOT)))
            if isinstance(node, ast.Assign | ast.AnnAssign):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                if any(
                    isinstance(t, ast.Name) and t.id in ("register_method", "METHODS")
                    for t in targets
                ):
                    defined.append(str(path.relative_to(ROOT)))
            if isinstance(node, ast.ImportFrom) and (node.module or "").endswith(
                "evaluation.methods"
            ):
                via.append(str(path.relative_to(ROOT)))
    assert sorted(set(defined)) == ["habitsim/transfer_methods.py"], defined
    assert not via, f"import habitsim.transfer_methods directly: {via}"


def test_lazy_methods_name_modules_of_the_learning_layer() -> None:
    """A lazily loaded method names a module that exists; the learned ones live in the
    learning layer (loaded on first call, so the core never imports torch)."""
    from habitsim.transfer_methods import METHODS, LazyFunction

    modules = _project_modules()
    learning = [i for i, (name, _) in enumerate(LAYERS) if name == "learning"][0]
    for m in METHODS.values():
        if isinstance(m.fn, LazyFunction):
            assert m.fn.module in modules, m
            assert layer_of(m.fn.module) == learning, m


def test_command_selections_come_from_the_registry() -> None:
    """Benchmarks and commands that offer a subset of the controllers offer registry names."""
    from habitsim.cli import retarget_cmd
    from habitsim.controllers import CONTROLLERS, REGISTRY
    from habitsim.evaluation.bench import balance, refine

    torque = {n for n, s in REGISTRY.items() if s.actuators == "torque"}
    assert set(balance.CONTROLLERS) == set(retarget_cmd.TRACK_CONTROLLERS) == torque
    assert set(refine.SURVIVAL_CONTROLLERS) <= set(CONTROLLERS)


#: What benchmarks compute with, and a command that only parses and prints never needs.
NUMERIC_MODULES = ("numpy", "scipy", "mujoco", "torch", "casadi")
#: Lines a ``habitsim/cli/bench_*.py`` may hold: its options, its calls and its print
#: formats (the longest, ``bench real``'s, is about 220).
CLI_BENCH_MAX_LINES = 300


def test_no_benchmark_logic_in_the_cli() -> None:
    """The benchmarks live in ``habitsim.evaluation.bench``; ``habitsim/cli/bench_*.py``
    only parse the options, call it and print. Two checks on every one of them:

    * it imports none of :data:`NUMERIC_MODULES`, at any level (module, function,
      ``TYPE_CHECKING``): measuring, aggregating or simulating needs them, parsing and
      formatting figures the library computed does not. A median, a rollout or a solve
      written in a command fails here.
    * it holds at most :data:`CLI_BENCH_MAX_LINES` lines, so that logic written without
      those imports (loops over clips, target arithmetic) cannot grow there unnoticed.
    """
    bad = []
    files = sorted((ROOT / "habitsim" / "cli").glob("bench_*.py"))
    assert files, "no habitsim/cli/bench_*.py found"
    for path in files:
        text = path.read_text(encoding="utf-8")
        name = path.relative_to(ROOT)
        for node in ast.walk(ast.parse(text, filename=str(path))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            bad += [
                f"{name}:{node.lineno}: imports {n}"
                for n in names
                if n.split(".")[0] in NUMERIC_MODULES
            ]
        lines = len(text.splitlines())
        if lines > CLI_BENCH_MAX_LINES:
            bad.append(f"{name}: {lines} lines > {CLI_BENCH_MAX_LINES}")
    assert not bad, "benchmark logic belongs in habitsim.evaluation.bench:\n" + "\n".join(bad)


#: Most lines of a module of the library (habitsim/, controllers/, evaluation/,
#: mjcf_models/): beyond it a module holds more than one concept; split it by concept.
MODULE_MAX_LINES = 800
#: Per-module limits below :data:`MODULE_MAX_LINES` (path relative to the repository):
#: the learning half of a transfer, its stance logic in :mod:`habitsim.stance`.
MODULE_LIMITS = {"habitsim/models/transfer.py": 700}


def test_no_module_over_the_size_limit() -> None:
    """No module of the library is longer than :data:`MODULE_MAX_LINES` lines (or its own
    limit in :data:`MODULE_LIMITS`); the failure lists each offender with its count."""
    bad = []
    for folder in ("habitsim", *BARE):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            name = str(path.relative_to(ROOT))
            limit = MODULE_LIMITS.get(name, MODULE_MAX_LINES)
            lines = len(path.read_text(encoding="utf-8").splitlines())
            if lines > limit:
                bad.append(f"{name}: {lines} lines > {limit}")
    assert all((ROOT / name).is_file() for name in MODULE_LIMITS), "a limit names no module"
    assert not bad, "modules over the size limit (split them by concept):\n" + "\n".join(bad)


@pytest.mark.parametrize("name", ["servo", "servo+id+stance", "pd"])
def test_registry_builds_every_kind(name: str) -> None:
    from habitsim.controllers import Controller, make_controller
    from habitsim.sim import servo_model, species_model

    base = species_model("dog")
    model = servo_model(base) if name.startswith("servo") else base
    ctl = make_controller(name, model)
    assert isinstance(ctl, Controller)


# ------------------------------------------------------------------------- import graph
#: Source folder -> installed package (setup.py's ROOTS).
SOURCES = {
    "habitsim": "habitsim",
    "controllers": "habitsim.controllers",
    "evaluation": "habitsim.evaluation",
    "mjcf_models": "habitsim.mjcf_models",
}

#: The layers, bottom to top (docs/architecture.md): a module may import its own layer and
#: the layers below, never one above. Looked up by the longest matching module prefix.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    (
        "core",
        (
            "habitsim.errors",
            "habitsim.physics_constants",
            "habitsim.fileio",
            "habitsim.rotations",
            "habitsim.skeleton",
            "habitsim.species",
            "habitsim.catalog",
            "habitsim.motion",
            "habitsim.contacts",
            "habitsim.hinges",
            "habitsim.body",
            "habitsim.ik",
            "habitsim.stance",
            "habitsim.gait_stats",
            "habitsim.gaits",
            "habitsim.transfer_methods",
            "habitsim.bvh",
            "habitsim.gltf",
            "habitsim.bvh_mapping",
            "habitsim.render",
            "habitsim.workers",
        ),
    ),
    (
        "physics",
        ("habitsim.mjcf_models", "habitsim.qpos", "habitsim.mjutils", "habitsim.controllers"),
    ),
    ("metrics", ("habitsim.metrics",)),
    (
        "stages",
        (
            "habitsim.refine",
            "habitsim.sim",
            "habitsim.retarget",
            "habitsim.dataset",
            "habitsim.dataset_import",
            "habitsim.testing",
            "habitsim.pytest_plugin",
        ),
    ),
    ("learning", ("habitsim.models",)),
    (
        "benchmark",
        (
            "habitsim.pipeline",
            "habitsim.evaluation",
            "habitsim.evaluation.rows",
            "habitsim.evaluation.bench",
        ),
    ),
    ("apps", ("habitsim.cli", "habitsim.__main__", "habitsim.examples")),
)
#: The package itself (``habitsim/__init__.py``): the facade above every layer, which any
#: submodule's import runs first anyway; importing it is not an upward import.
FACADE = "habitsim"


def _project_modules() -> dict[str, tuple[Path, bool]]:
    """Installed module name -> (source file, is a package)."""
    out: dict[str, tuple[Path, bool]] = {}
    for folder, name in SOURCES.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            parts = list(path.relative_to(ROOT / folder).with_suffix("").parts)
            package = parts[-1] == "__init__"
            if package:
                parts = parts[:-1]
            out[".".join([name, *parts])] = (path, package)
    return out


def import_graph() -> dict[str, dict[str, int]]:
    """module -> {imported project module: line}, every import of the module's AST
    (module level, function level, ``TYPE_CHECKING`` blocks, ``import_module("...")``)."""
    modules = _project_modules()

    def known(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, dict[str, int]] = {}
    for mod, (path, package) in modules.items():
        pkg = mod if package else mod.rpartition(".")[0]

        def absolute(name: str, level: int, pkg: str = pkg) -> str:
            if not level:
                return name
            base = pkg.split(".")[: len(pkg.split(".")) - (level - 1)]
            return ".".join([*base, name] if name else base)

        edges: dict[str, int] = {}
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = absolute(node.module or "", node.level)
                names = [
                    f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                    for a in node.names
                ]
            elif (
                isinstance(node, ast.Call)
                and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module"
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str)
            ):
                name = node.args[0].value
                level = len(name) - len(name.lstrip("."))
                names = [absolute(name.lstrip("."), level)]
            for name in names:
                target = known(name)
                if target is not None and target != mod:
                    edges.setdefault(target, node.lineno)
        graph[mod] = edges
    return graph


def _cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(graph[start]))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(graph[w])))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def layer_of(module: str) -> int | None:
    """Index of the module's layer in :data:`LAYERS` (longest prefix), None if unlisted."""
    best, found = -1, None
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best:
                best, found = len(p), i
    return found


def test_import_graph_sees_every_kind_of_import() -> None:
    graph = import_graph()
    assert "habitsim.controllers.base" in graph["habitsim.controllers"]  # relative, package
    assert "habitsim.metrics.simulated" in graph["habitsim.sim.result"]  # function level
    assert "habitsim.refine" in graph["habitsim"]  # import_module(".refine", __name__)
    assert _cycles({"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 1}, "d": {"a": 1}}) == [
        ["a", "b", "c"]
    ]


def test_no_import_cycles() -> None:
    cycles = _cycles(import_graph())
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_every_module_has_a_layer() -> None:
    missing = [m for m in import_graph() if m != FACADE and layer_of(m) is None]
    assert not missing, "add to LAYERS (and docs/architecture.md): " + ", ".join(missing)


def test_layers_run_one_way() -> None:
    bad = []
    for mod, edges in import_graph().items():
        here = layer_of(mod)
        if mod == FACADE or here is None:
            continue
        for target, line in edges.items():
            there = layer_of(target)
            if target != FACADE and there is not None and there > here:
                bad.append(
                    f"{mod}:{line} ({LAYERS[here][0]}) imports {target} ({LAYERS[there][0]})"
                )
    assert not bad, "imports of a higher layer:\n" + "\n".join(sorted(bad))
