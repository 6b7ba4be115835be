"""docs/architecture.md is the map of the package: every module it names exists, and
every module of the package is on the map (so the map cannot rot in either direction)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "architecture.md"
#: Paths named in the doc: `tactbench/x.py`, `tactbench/x/` (a folder), `plugins/...`.
PATH_RE = re.compile(r"`((?:tactbench|plugins|benchmarks|tests|docs)/[\w./-]*)`")


def named_paths() -> list[str]:
    return sorted(set(PATH_RE.findall(DOC.read_text())))


def test_the_map_names_modules():
    assert len(named_paths()) >= 30


def test_every_module_the_map_names_exists():
    missing = [p for p in named_paths() if not (REPO / p).exists()]
    assert not missing, f"docs/architecture.md names paths that do not exist: {missing}"


def test_every_module_of_the_package_is_on_the_map():
    """A folder named on the map covers its modules, but for the runner: each of its
    modules is named, with its job (the walk of a run goes through them)."""
    named = set(named_paths())
    folders = {p.rstrip("/") for p in named if p.endswith("/")}
    unlisted = []
    for path in sorted((REPO / "tactbench").rglob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        if path.name == "__init__.py" or path.name == "__main__.py":
            continue
        covered = path.parent.relative_to(REPO).as_posix() in folders \
            and not rel.startswith("tactbench/runner/")
        if rel not in named and not covered:
            unlisted.append(rel)
    assert not unlisted, f"modules missing from docs/architecture.md: {unlisted}"


# ------------------------------------------------------------------ imports

#: Where each part of the package sits in the pipeline: folder (or module) → stage.
#: Sensors, CAN and datasets are all *sources* of recordings.
STAGE_OF = {"sensors": "sources", "can": "sources", "datasets": "sources", "data": "data",
            "encoders": "encoders", "classifiers": "classifiers", "runner": "runner",
            "live": "live", "commands": "commands"}
#: stage → the stages it may import: data moves down the pipeline.
MAY_IMPORT = {
    "data": set(),
    "sources": {"data"},
    "encoders": {"data"},
    "classifiers": {"data"},
    "runner": {"data", "sources", "encoders", "classifiers"},
    "live": {"data", "sources", "encoders", "classifiers"},
    "commands": {"data", "sources", "encoders", "classifiers", "runner", "live", "faces"},
}
#: Top-level modules that face the user or the plugin author; every other top-level
#: module (errors, paths, budget, integrity, specs, registry, plugins, contracts, ...) is
#: shared ground, which any stage may import and which imports no stage.
FACES = {"cli", "clidoc", "testing", "fuzzing", "__main__"}

#: What may be imported inside a function: heavy or optional third-party libraries, kept
#: off the start-up path (numpy too, for the modules ``tactbench --help`` imports).
LAZY = {"torch", "torchvision", "kornia", "cv2", "can", "matplotlib", "dask", "distributed",
        "scipy", "sklearn", "skimage", "safetensors", "timm", "threadpoolctl", "rich",
        "pytest", "hypothesis", "numpy", "tomli", "psutil", "pandas", "pyarrow", "mlflow"}
#: tactbench's own modules that import torch at module level (the networks): importing one
#: is importing torch, so they too are imported inside the functions that use them, and
#: the classifiers that do not train a network never load torch.
HEAVY_MODULES = {"tactbench.classifiers.nets", "tactbench.classifiers.efficientnet"}
#: Import cycles among tactbench's modules still to break (helper runner-house's); only
#: shrinks.
KNOWN_CYCLES: list[list[str]] = []


def module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted((REPO / "tactbench").rglob("*.py"))}


def imports_of(path: Path) -> list[tuple[str, bool, int]]:
    """``(module, inside_a_function, line)`` for each tactbench module ``path`` imports (a name
    imported from a package counts as its submodule when it is one); imports under
    ``if TYPE_CHECKING:`` are not run and are left out."""
    found: list[tuple[str, bool, int]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                       ast.Lambda))
            if isinstance(child, ast.Import):
                found.extend((a.name, inside, child.lineno) for a in child.names
                             if a.name.split(".")[0] == "tactbench")
            elif isinstance(child, ast.ImportFrom) and child.level:
                raise AssertionError(f"{path}: relative import; tactbench imports by full name")
            elif isinstance(child, ast.ImportFrom) and child.module and \
                    child.module.split(".")[0] == "tactbench":
                for alias in child.names:
                    sub = f"{child.module}.{alias.name}"
                    found.append((sub if sub in MODULES else child.module, inside, child.lineno))
            visit(child, inside)

    visit(ast.parse(path.read_text()), False)
    return found


def stage_of(module: str) -> str:
    parts = module.split(".")
    if len(parts) < 2:
        return "shared"
    if parts[1] in STAGE_OF:
        return STAGE_OF[parts[1]]
    return "faces" if parts[1] in FACES else "shared"


def test_data_moves_down_the_pipeline():
    """Every stage imports only the stages below it; shared ground imports no stage."""
    wrong = []
    for module, path in MODULES.items():
        stage = stage_of(module)
        if stage == "faces":
            continue
        allowed = MAY_IMPORT.get(stage, set()) | {stage, "shared"}
        for target, _, _ in imports_of(path):
            if stage_of(target) not in allowed:
                wrong.append(f"{module} ({stage}) imports {target} ({stage_of(target)})")
    assert not wrong, "an import against the pipeline's direction: " + "; ".join(wrong)


def test_every_stage_and_shared_module_has_a_place():
    assert set(STAGE_OF.values()) == set(MAY_IMPORT)  # every stage has its rule
    for module in MODULES:
        parts = module.split(".")
        if len(parts) > 2:  # inside a folder: the folder must be a stage
            assert parts[1] in STAGE_OF, f"{module}: folder '{parts[1]}' is no stage"


def import_graph() -> dict[str, set[str]]:
    """module → the tactbench modules it imports (at module level or in functions)."""
    return {module: {target for target, _, _ in imports_of(path) if target != module}
            for module, path in MODULES.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return sorted(found)


def test_the_cycle_finder_finds_cycles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"f"}, "f": {"e"}}
    assert cycles(graph) == [["a", "b", "c"], ["e", "f"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_among_tactbench_modules():
    """Counting imports inside functions too: a function-level import does not make a
    cycle go away, it only hides it."""
    found = cycles(import_graph())
    new = [c for c in found if c not in KNOWN_CYCLES]
    assert not new, f"import cycles: {new}"
    gone = [c for c in KNOWN_CYCLES if c not in found]
    assert not gone, f"cycles broken, remove them from KNOWN_CYCLES: {gone}"


def function_level_imports(path: Path) -> list[tuple[str, int]]:
    """``(module, line)`` of each import inside a function of ``path`` (a name imported
    from a tactbench package counts as its submodule when it is one)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            for inner in ast.walk(node):
                if isinstance(inner, ast.Import):
                    found.append((inner.names[0].name, inner.lineno))
                elif isinstance(inner, ast.ImportFrom):
                    module = inner.module or ""
                    subs = [f"{module}.{a.name}" for a in inner.names]
                    found.append((subs[0] if subs[0] in MODULES else module, inner.lineno))
    return sorted(set(found), key=lambda item: item[1])


def test_the_function_level_import_finder_sees_nested_functions(tmp_path):
    (tmp_path / "m.py").write_text("import os\ndef f():\n    import torch\n"
                                   "    def g():\n        from tactbench import errors\n")
    assert function_level_imports(tmp_path / "m.py") == [("torch", 3), ("tactbench.errors", 5)]


def test_tactbench_modules_are_imported_at_module_level():
    """Imports inside functions are for heavy third-party libraries only (:data:`LAZY`, and
    tactbench's torch modules, :data:`HEAVY_MODULES`); tactbench's own modules and the
    standard library are imported at the top, where the dependency shows."""
    wrong = [f"{path.relative_to(REPO).as_posix()}:{line} imports {module}"
             for path in MODULES.values()
             for module, line in function_level_imports(path)
             if module.split(".")[0] not in LAZY and module not in HEAVY_MODULES]
    assert not wrong, "imports inside functions of what is not a heavy library: " + \
        "; ".join(wrong)


def test_the_heavy_modules_are_heavy():
    """A module is on :data:`HEAVY_MODULES` only while it imports torch at module level."""
    for module in sorted(HEAVY_MODULES):
        tree = ast.parse(MODULES[module].read_text())
        tops = {alias.name.split(".")[0] for node in tree.body if isinstance(node, ast.Import)
                for alias in node.names}
        tops |= {(node.module or "").split(".")[0] for node in tree.body
                 if isinstance(node, ast.ImportFrom)}
        assert "torch" in tops, f"{module} no longer imports torch: take it off HEAVY_MODULES"


def test_the_runner_and_live_know_components_only_through_the_registry():
    """No module of the runner or of live imports a module a built-in component lives in."""
    from tactbench.plugins import load_registry

    targets = {c.target.partition(":")[0] for c in load_registry().components()
               if c.distribution == "tactbench"}
    wrong = [f"{module} imports {target}" for module, path in MODULES.items()
             if stage_of(module) in ("runner", "live")
             for target, _, _ in imports_of(path) if target in targets]
    assert not wrong, "; ".join(wrong)


def test_importing_tactbench_has_no_side_effects_on_the_import_system():
    """No finder on sys.meta_path, no hooks: ``import tactbench`` only defines names."""
    import subprocess
    import sys

    code = ("import sys; before = list(sys.meta_path), list(sys.path_hooks)\n"
            "import tactbench\n"
            "assert (list(sys.meta_path), list(sys.path_hooks)) == before\n"
            "print('clean')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.stdout.strip() == "clean", out.stderr


# ------------------------------------------------------------------ shape

#: The longest a function may be (its ``def`` to its last line) and a module, in lines.
MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 600
#: Today's offenders in modules other helpers of issue 27 are reshaping in parallel
#: (``path`` or ``path::function``); only shrinks: the lead empties it after merging.
KNOWN_LONG: set[str] = set()
#: The benchmark scripts: held to the function limit too (a script is not a module of
#: the package, so the module limit is not theirs).
BENCHMARKS = sorted((REPO / "benchmarks").glob("*.py"))


def too_long(path: Path) -> list[str]:
    """``path`` (when over :data:`MAX_MODULE_LINES`) and ``path::function`` for each
    function over :data:`MAX_FUNCTION_LINES`, with their lengths."""
    rel = path.relative_to(REPO).as_posix() if path.is_relative_to(REPO) else path.name
    text = path.read_text()
    found = []
    if len(text.splitlines()) > MAX_MODULE_LINES:
        found.append((rel, len(text.splitlines())))
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            length = node.end_lineno - node.lineno + 1
            if length > MAX_FUNCTION_LINES:
                found.append((f"{rel}::{node.name}", length))
    return found


def test_the_length_finder_measures_functions_and_modules(tmp_path):
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    (tmp_path / "m.py").write_text(f"def long():\n{body}\ndef short():\n    pass\n")
    assert too_long(tmp_path / "m.py") == [("m.py::long", MAX_FUNCTION_LINES + 1)]
    (tmp_path / "big.py").write_text("x = 1\n" * (MAX_MODULE_LINES + 1))
    assert too_long(tmp_path / "big.py") == [("big.py", MAX_MODULE_LINES + 1)]


def test_the_function_limit_reads_the_benchmarks():
    assert len(BENCHMARKS) >= 10 and REPO / "benchmarks" / "reports.py" in BENCHMARKS


def test_no_function_over_80_lines_and_no_module_over_600():
    found = {name: length for path in MODULES.values() for name, length in too_long(path)}
    found |= {name: length for path in BENCHMARKS for name, length in too_long(path)
              if "::" in name}
    new = {name: length for name, length in found.items() if name not in KNOWN_LONG}
    assert not new, f"too long (lines; a function ≤ {MAX_FUNCTION_LINES}, a module ≤ " \
                    f"{MAX_MODULE_LINES}): {new}"
    gone = sorted(KNOWN_LONG - set(found))
    assert not gone, f"short enough now, remove them from KNOWN_LONG: {gone}"


#: The runner's rooms → the rooms each may import (besides itself).
ROOM_MAY_IMPORT = {"execution": set(), "analysis": {"execution"},
                   "presentation": {"execution", "analysis"}}


def room_of(module: str) -> str | None:
    parts = module.split(".")
    return parts[2] if len(parts) > 3 and parts[:2] == ["tactbench", "runner"] \
        and parts[2] in ROOM_MAY_IMPORT else None


def test_the_runner_has_three_rooms_and_nothing_else_beside_them():
    """Every module of tactbench/runner/ sits in one of the three rooms, but the
    package's __init__, orchestrate and forecasting, which compose them."""
    loose = sorted(p.name for p in (REPO / "tactbench" / "runner").glob("*.py"))
    assert loose == ["__init__.py", "forecasting.py", "orchestrate.py"]
    for room in ROOM_MAY_IMPORT:
        assert list((REPO / "tactbench" / "runner" / room).glob("*.py")), room


def test_the_runner_rooms_point_one_way():
    """Execution imports neither other room; analysis never imports presentation."""
    wrong = []
    for module, path in MODULES.items():
        room = room_of(module)
        if room is None:
            continue
        for target, _, line in imports_of(path):
            other = room_of(target) if target.startswith("tactbench.runner.") else None
            if target in ("tactbench.runner", "tactbench.runner.orchestrate",
                          "tactbench.runner.forecasting"):
                wrong.append(f"{module}:{line} imports {target} (the rooms' composer)")
            elif other and other != room and other not in ROOM_MAY_IMPORT[room]:
                wrong.append(f"{module}:{line} ({room}) imports {target} ({other})")
    assert not wrong, "an import against the runner's rooms: " + "; ".join(wrong)


def test_the_room_rule_sees_a_wrong_arrow():
    assert room_of("tactbench.runner.execution.cell") == "execution"
    assert room_of("tactbench.runner.orchestrate") is None
    assert "presentation" not in ROOM_MAY_IMPORT["analysis"]


# ------------------------------------------------------------------ analysis decides

#: What presentation may take from analysis besides its records' classes and constants:
#: readers of what analysis decided (a record in, a fact of it out), none of which decides.
PRESENTATION_READS = {"plain_t", "beyond_looks", "chosen_tests", "read_comparisons",
                      "failed_cells", "comparison_record"}
#: Analysis's functions that decide (from rows to summaries, verdicts, looks): only
#: orchestrate calls them, never presentation.
DECIDERS = {"analyse", "comparisons", "replay", "summarise", "variance_decomposition",
            "run_level_tests", "family_look", "sequential_verdict"}
#: What orchestrate takes from presentation: the report of an analysis and its files.
ORCHESTRATE_FROM_PRESENTATION = {"Report", "render", "write_report", "refresh_parquet",
                                 "EXTRA"}
#: The decided parts of a report, which orchestrate reads from the analysis instead.
DECIDED_ATTRIBUTES = {"rows", "summaries", "comparisons", "looks", "history", "ok", "failed",
                      "statistics", "variance", "budget_stop"}
#: The parts of execution that do the work (plan, cache, encode, run cells, decide the
#: workers): analysis reads execution's records and never these (``plan`` composes them
#: with analysis in runner/forecasting.py, as orchestrate does for a run).
WORK = ("planning", "cache", "entries", "leases", "estimate", "workers", "executors",
        "cell", "system")


def test_analysis_reads_records_and_never_does_the_work():
    wrong = [f"{module}:{node.lineno} imports {node.module}"
             for module, path in MODULES.items() if room_of(module) == "analysis"
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.ImportFrom) and any(
                 (node.module or "") == f"tactbench.runner.execution.{w}" for w in WORK)]
    assert not wrong, "analysis does execution's work: " + "; ".join(wrong)


def names_from(path: Path, package: str) -> list[tuple[str, int]]:
    """``(name, line)`` for each name ``path`` imports from a module under ``package``."""
    return [(alias.name, node.lineno) for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(package)
            for alias in node.names]


def test_the_name_finder_sees_names(tmp_path):
    (tmp_path / "m.py").write_text("from tactbench.runner.analysis.report import analyse\n"
                                   "def f():\n    from tactbench.errors import InputError\n")
    assert names_from(tmp_path / "m.py", "tactbench.runner.analysis") == [("analyse", 1)]


def test_presentation_only_renders_what_analysis_decided():
    """Presentation takes from analysis the records it shows (classes, constants) and
    readers of them; it never runs the analysis (summaries, comparisons, looks)."""
    assert not PRESENTATION_READS & DECIDERS
    wrong = [f"{module}:{line} imports {name}" for module, path in MODULES.items()
             if room_of(module) == "presentation"
             for name, line in names_from(path, "tactbench.runner.analysis")
             if not name[0].isupper() and name not in PRESENTATION_READS]
    assert not wrong, "presentation runs analysis (analysis decides, presentation " \
                      "renders): " + "; ".join(wrong)


def test_orchestrate_reads_its_decisions_from_analysis():
    """Orchestrate imports from presentation only the report and its writing, and reads
    nothing decided (rows, comparisons, looks, whether a look answered the run) off a
    rendered report: those come from its analysis."""
    path = MODULES["tactbench.runner.orchestrate"]
    taken = {name for name, _ in names_from(path, "tactbench.runner.presentation")}
    assert "render" in taken and taken <= ORCHESTRATE_FROM_PRESENTATION, taken
    assert {"analyse"} <= {name for name, _ in names_from(path, "tactbench.runner.analysis")}
    wrong = [f"{node.lineno}: report.{node.attr}"
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
             and node.value.id == "report" and node.attr in DECIDED_ATTRIBUTES]
    assert not wrong, "orchestrate reads a decision off the rendered report: " + \
        "; ".join(wrong)


# ------------------------------------------------------------------ the public face

#: Code outside the runner that is held to its public face: the package's other modules,
#: the benchmark scripts and the plugins shipped beside it (the tests of the rooms may
#: reach inside them).
OUTSIDE_THE_RUNNER = sorted(
    [p for m, p in MODULES.items() if stage_of(m) != "runner"] + BENCHMARKS
    + list((REPO / "plugins").glob("*/src/**/*.py")))


def deep_runner_imports(path: Path) -> list[str]:
    """``line: module`` for each import of ``path`` that reaches inside the runner (any
    module under ``tactbench.runner`` but the package, its public face)."""
    return [f"{line}: {target}" for target, _, line in imports_of(path)
            if target.startswith("tactbench.runner.")]


def test_the_deep_import_finder_sees_one(tmp_path):
    (tmp_path / "m.py").write_text(
        "from tactbench.runner import Scene, run\n"
        "def f():\n    from tactbench.runner.analysis.power import power\n"
        "from tactbench.runner import orchestrate\n")
    assert deep_runner_imports(tmp_path / "m.py") == [
        "3: tactbench.runner.analysis.power", "4: tactbench.runner.orchestrate"]


def test_nothing_outside_the_runner_imports_a_room():
    """Commands, benchmarks, plugins and the package's other modules import the runner's
    names from ``tactbench.runner`` (its ``__all__``), never from a room's module, so the
    rooms can be rearranged behind that face."""
    assert any(p.parts[-2] == "tactbench_mlflow" for p in OUTSIDE_THE_RUNNER)
    assert REPO / "tactbench" / "commands" / "run.py" in OUTSIDE_THE_RUNNER
    wrong = [f"{path.relative_to(REPO).as_posix()}:{hit}" for path in OUTSIDE_THE_RUNNER
             for hit in deep_runner_imports(path)]
    assert not wrong, "a runner room imported from outside the runner (import it from " \
                      "tactbench.runner, adding it to __all__): " + "; ".join(wrong)


def test_the_public_face_exports_what_it_imports():
    """Every name of ``tactbench.runner.__all__`` is there, once (docs/api.md documents
    them all: tactbench.apidoc)."""
    import tactbench.runner as runner

    assert len(set(runner.__all__)) == len(runner.__all__)
    missing = [n for n in runner.__all__ if not hasattr(runner, n)]
    assert not missing, missing
