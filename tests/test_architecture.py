"""Architecture facts: a light core, one name per module, one controller registry."""

from __future__ import annotations

import ast
import re
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
            "habitsim.folders",
            "habitsim.jsonfile",
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
            "habitsim.activity",
            "habitsim.gaits",
            "habitsim.transfer_methods",
            "habitsim.bvh",
            "habitsim.gltf_container",
            "habitsim.gltf",
            "habitsim.gltf_export",
            "habitsim.bvh_mapping",
            "habitsim.source",
            "habitsim.bvh_mapping.export",
            "habitsim.fromclip",
            "habitsim.render",
            "habitsim.render_side",
            "habitsim.workers",
            "habitsim.threads",
            "habitsim.timelimit",
        ),
    ),
    (
        "physics",
        (
            "habitsim.mjcf_models",
            "habitsim.qpos",
            "habitsim.mjutils",
            "habitsim.controllers",
            "habitsim.fromclip.make",
        ),
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
            "habitsim.captions",
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
            "habitsim.evaluation.score",
            "habitsim.evaluation.score_report",
            "habitsim.evaluation.outputs",
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


# ---------------------------------------------------------------------- tuning constants
#: Why a module may hold module-level UPPER_CASE numeric or bool constants, by kind. A
#: tuning knob (a number that changes what an algorithm computes) is never one of them:
#: it is a field of its stage's frozen options object (``ConformPolicy``,
#: ``RefineOptions``, ``BalanceConfig``, ``ContactOptions``, ``FallOptions``,
#: ``GuardOptions``, ``BuildRules``, …), passed as an argument with its default.
_LIMITS = "limits: the largest input a reader or a command accepts (a guard, not a knob)"
_FORMAT = "format: a file or output format's version, sizes or layout"
_METRIC = "definitions: a metric's definition (docs/metrics.md), changed only with its docs"
_TARGET = "benchmark targets and the benchmark's own definitions (docs/benchmarks.md)"
_DEFINES = "definitions: dimensions, modes or index layout the code is written for"

#: Modules allowed to hold such constants, every constant of the module (path from the
#: repository root; a folder ends with "/").
CONSTANT_MODULES: dict[str, str] = {
    "habitsim/physics_constants.py": "physical constants and the shared contact convention",
    "habitsim/bvh/limits.py": _LIMITS,
    "habitsim/motion.py": _FORMAT + "; " + _LIMITS,
    "habitsim/cli/": "the command line: exit codes, output widths, argument bounds",
    "habitsim/dataset/records.py": _FORMAT + "; " + _LIMITS + "; the train/val split rule",
    "habitsim/dataset_import.py": _LIMITS,
    "habitsim/errors.py": _FORMAT + " (message lengths)",
    "habitsim/species.py": _LIMITS,
    "habitsim/testing.py": _FORMAT + " (golden figure files)",
    "habitsim/models/checkpoint.py": _FORMAT + " (checkpoint version)",
    "habitsim/captions/store.py": _FORMAT + " (captions file version)",
    "habitsim/captions/phrasing.py": _FORMAT + " (the levels of detail a caption has)",
    "habitsim/models/features.py": _FORMAT + " (feature version and layout)",
    "habitsim/refine/layout.py": _DEFINES + " (the NLP's variable layout)",
    "habitsim/metrics/": _METRIC,
    "habitsim/gltf.py": _FORMAT + " (end-site length, a rotation's uniformity tolerance)",
    "habitsim/gltf_container.py": _FORMAT + " (GLB chunk types, the spec's largest byte stride)",
    "evaluation/bench/": _TARGET,
    "evaluation/distribution.py": _METRIC + " (pair counts, numerical tolerances)",
    "evaluation/config.py": _FORMAT + "; the default run's size",
    "evaluation/evaluator.py": _FORMAT + " (evaluator config version)",
    "evaluation/planning.py": "the default data set of a run given none (docs/evaluation.md)",
}

#: Single constants allowed in other modules: (path, name) → why.
CONSTANT_NAMES: dict[tuple[str, str], str] = {
    ("habitsim/sim/model.py", "TOUCH_THRESHOLD_MG"): _METRIC + " (a simulated foot contact)",
    ("habitsim/models/model.py", "ROTATION_INPUT_CLIP"): "the trained network's input "
    "definition (the default of a model's rotation_input_clip; a checkpoint is trained with it)",
    ("habitsim/models/model.py", "PATH_DIM"): _DEFINES,
    ("habitsim/models/model.py", "HEADING_DIM"): _DEFINES,
    ("habitsim/models/transfer.py", "PRIOR_DRAWS_KEPT"): "a cache's size (a limit)",
    ("habitsim/models/t2m_data.py", "_FORMAT"): _FORMAT + " (code set version)",
    ("habitsim/models/t2m_train.py", "_VERSION"): _FORMAT + " (text-to-motion checkpoint version)",
    ("evaluation/t2m_evaluator.py", "CONFIG_FORMAT_VERSION"): _FORMAT
    + " (text–motion evaluator config version)",
    ("habitsim/gait_stats.py", "GALLOP_FROUDE"): _METRIC + " (the trot → gallop Froude number)",
    ("habitsim/gait_stats.py", "PEAK_SPAN_S"): _METRIC + " (the span of the peak Froude number)",
    ("habitsim/bvh_mapping/result.py", "CONFIDENCE_WARN"): "a report's warning threshold",
    ("habitsim/render.py", "DEFAULT_COLOUR"): _FORMAT + " (an RGB colour)",
    ("habitsim/refine/cache.py", "MAX_CACHED_PROBLEMS"): "a cache's size (memory, not results)",
    ("habitsim/retarget/clip.py", "CLIP_VERSION"): _FORMAT + " (robot clip files)",
    ("habitsim/workers.py", "WATCHDOG_INTERVAL_S"): "a process watchdog's polling period",
    ("habitsim/workers.py", "_PR_SET_PDEATHSIG"): "an operating-system constant (prctl)",
    ("controllers/contact_state.py", "STANCE"): _DEFINES + " (leg modes)",
    ("controllers/contact_state.py", "SWING"): _DEFINES + " (leg modes)",
    ("controllers/contact_state.py", "SEEK"): _DEFINES + " (leg modes)",
    ("controllers/balance.py", "AT_LIMIT_SHARE"): "definition of a reported statistic",
    ("controllers/feedforward.py", "_CONE_EDGES"): _DEFINES + " (friction pyramid edges)",
    ("controllers/mpc.py", "NX"): _DEFINES + " (the single rigid body's state size)",
    ("mjcf_models/builder.py", "PREVIEW_SIZE"): _FORMAT + " (preview image)",
    ("mjcf_models/builder.py", "PREVIEW_DISTANCE"): _FORMAT + " (preview image)",
    ("mjcf_models/builder.py", "PREVIEW_VIEW"): _FORMAT + " (preview image)",
    ("habitsim/gaits/generator.py", "GENERATOR_VERSION"): _FORMAT
    + " (the synthetic generator's version, stored in its clips and data sets)",
    ("habitsim/gaits/actions.py", "_AERIAL_DUTY"): _DEFINES + " (a gait below this duty "
    "factor has an aerial phase: which species have the jump action, not how it is made)",
}

_UPPER = re.compile(r"_?[A-Z][A-Z0-9_]*\Z")


def _is_number(node: ast.expr) -> bool:
    """A numeric or bool literal, arithmetic over literals and other constants' names, or
    a tuple / list of those (a bare name or attribute alone is an alias, not a value)."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, (bool, int, float)) and not isinstance(node.value, str)
    if isinstance(node, ast.UnaryOp):
        return _is_number(node.operand)
    if isinstance(node, ast.BinOp):
        sides = (node.left, node.right)
        return all(_is_number(s) or isinstance(s, ast.Name) for s in sides) and any(
            _is_number(s) or isinstance(s, ast.Name) for s in sides
        )
    if isinstance(node, (ast.Tuple, ast.List)):
        return bool(node.elts) and all(_is_number(e) for e in node.elts)
    return False


def _numeric_constants() -> list[tuple[str, str, int]]:
    """(path, name, line) of every module-level UPPER_CASE numeric or bool constant of
    the library (``habitsim/``, ``controllers/``, ``evaluation/``, ``mjcf_models/``)."""
    out = []
    for folder in ("habitsim", *BARE):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.parse(path.read_text(encoding="utf-8")).body:
                if isinstance(node, ast.Assign) and len(node.targets) == 1:
                    target, value = node.targets[0], node.value
                elif isinstance(node, ast.AnnAssign) and node.value is not None:
                    target, value = node.target, node.value
                else:
                    continue
                if isinstance(target, ast.Name) and _UPPER.match(target.id) and _is_number(value):
                    out.append((rel, target.id, node.lineno))
    return out


def _allowed(path: str, name: str) -> bool:
    return (path, name) in CONSTANT_NAMES or any(
        path == m or (m.endswith("/") and path.startswith(m)) for m in CONSTANT_MODULES
    )


def test_no_tuning_constants_outside_options() -> None:
    """A module-level UPPER_CASE number or bool of the library is a definition, a limit, a
    format, a physical constant or a benchmark target, listed with its reason in
    :data:`CONSTANT_MODULES` / :data:`CONSTANT_NAMES`; a tuning knob is a field of its
    stage's options object (docs/architecture.md, "Where new things go")."""
    found = _numeric_constants()
    bad = [f"{p}:{line}: {n}" for p, n, line in found if not _allowed(p, n)]
    assert not bad, (
        "module-level numeric constants outside the allow-list (a tuning knob goes into "
        "its stage's options object; a definition, limit or format is listed with its "
        "reason in tests/test_architecture.py):\n" + "\n".join(bad)
    )
    # the lists stay honest: every entry names something that exists
    names = {(p, n) for p, n, _ in found}
    stale = [f"{p}: {n}" for p, n in CONSTANT_NAMES if (p, n) not in names]
    stale += [m for m in CONSTANT_MODULES if not any(p == m or p.startswith(m) for p, _ in names)]
    assert not stale, "allow-list entries that no longer exist:\n" + "\n".join(stale)
    assert all(CONSTANT_MODULES.values()) and all(CONSTANT_NAMES.values())  # a reason each


def test_the_tuning_constant_check_can_fail() -> None:
    """The check's detector sees the forms a knob takes."""
    for src in ("X = 0.3", "X: float = 2", "_X = -1e-3", "X = True", "X = (0.1, 0.2)", "X = Y * 4"):
        assert _is_number(ast.parse(src).body[0].value), src  # type: ignore[attr-defined]
    for src in ("X = 'a'", "X = Y", "X = f(0.3)", "X = {'a': 1}", "X = Path('a') / 'b'"):
        assert not _is_number(ast.parse(src).body[0].value), src  # type: ignore[attr-defined]
    assert not _allowed("habitsim/pipeline.py", "WORSE_MPJPE_RATIO")
