"""The package's layers stay true: every module is placed in a layer, imports point only
down or sideways (never up), there are no import cycles, and only the entry points import
the command line. Pure ``ast``: nothing of the package (nor JAX) is imported.

Every import counts: at module level and inside functions (a lazy import still couples two
modules), absolute and relative. Importing ``pkg.sub._mod`` from outside ``pkg.sub`` also
runs ``pkg/sub/__init__.py`` first, so it counts as an import of that package too.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

PACKAGE = "cdog_jax"
ROOT = Path(__file__).resolve().parents[1] / PACKAGE

# Low to high. A module may import its own layer and the layers below it. An entry ending in
# "." is a subpackage (all its modules); any other entry is one module. Entries that do not
# exist (yet) are tolerated. Keep in step with docs/ARCHITECTURE.md.
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("base", ("_types", "_expect", "_status", "_version", "cdog", "cdog._config", "cdog._options")),
    ("geometry", ("geometry.",)),
    ("stage", ("cdog._stage",)),
    ("stages", ("graph.", "refine.")),
    (
        "core",
        (
            "_result",
            "_runtime.",
            "_validate",
            "cdog.",
            "_method",
            "_associate",
            "people.",
            "tracking.",
        ),
    ),
    ("methods", ("baselines.",)),
    ("data", ("io.", "synthetic.", "metrics.")),
    ("harness", ("benchmark.", "calibration.")),
    ("viz", ("viz.",)),
    ("entry", ("cli.", "__init__", "__main__")),
]
# The command line is imported by nothing but these (``python -m cdog_jax`` runs it).
CLI = f"{PACKAGE}.cli"
CLI_IMPORTERS = {f"{PACKAGE}.__main__"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def _is_package(name: str, modules: dict[str, Path]) -> bool:
    return modules[name].name == "__init__.py"


def _imports(name: str, modules: dict[str, Path]) -> dict[str, int]:
    """The package modules ``name`` imports, each with the line of its first import."""
    tree = ast.parse(modules[name].read_text(encoding="utf-8"), filename=str(modules[name]))
    here = name if _is_package(name, modules) else name.rpartition(".")[0]
    found: dict[str, int] = {}

    def add(target: str, line: int) -> None:
        if target != name:
            found.setdefault(target, line)

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [(alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here.split(".")
                base = base[: len(base) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            targets = [(source, alias.name) for alias in node.names]
        else:
            continue
        for source, attribute in targets:
            if source != PACKAGE and not source.startswith(PACKAGE + "."):
                continue
            assert source in modules, (
                f"{modules[name]}:{node.lineno}: imports {source}, which does not exist"
            )
            target = f"{source}.{attribute}" if f"{source}.{attribute}" in modules else source
            add(target, node.lineno)
            # Importing a submodule from outside its package runs the package's __init__ first.
            package = target.rpartition(".")[0]
            while package and package != PACKAGE and not name.startswith(package + "."):
                add(package, node.lineno)
                package = package.rpartition(".")[0]
    return found


def _graph() -> tuple[dict[str, Path], dict[str, dict[str, int]]]:
    modules = _modules()
    return modules, {name: _imports(name, modules) for name in modules}


def _layer_of(name: str) -> int | None:
    relative = name[len(PACKAGE) + 1 :] if name != PACKAGE else "__init__"
    for rank, (_, entries) in enumerate(LAYERS):
        for entry in entries:
            if entry.endswith(".") and (relative == entry[:-1] or relative.startswith(entry)):
                return rank
            if relative == entry:
                return rank
    return None


def _where(modules: dict[str, Path], name: str, line: int) -> str:
    return f"{modules[name].relative_to(ROOT.parent)}:{line}"


def test_every_module_has_a_layer():
    unplaced = [name for name in _modules() if _layer_of(name) is None]
    assert not unplaced, (
        f"modules in no layer (add them to LAYERS here and in docs/ARCHITECTURE.md): {unplaced}"
    )


def test_no_import_from_a_higher_layer():
    modules, graph = _graph()
    upward = []
    for name, targets in graph.items():
        low = _layer_of(name)
        for target, line in targets.items():
            high = _layer_of(target)
            if low is not None and high is not None and high > low:
                upward.append(
                    f"{_where(modules, name, line)}: {name} ({LAYERS[low][0]}) imports "
                    f"{target} ({LAYERS[high][0]})"
                )
    assert not upward, "imports from a higher layer:\n" + "\n".join(upward)


def test_no_import_cycles():
    modules, graph = _graph()
    cycles = []
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(name: str) -> None:
        state[name] = 1
        path.append(name)
        for target in sorted(graph[name]):
            if state.get(target) == 1:
                loop = path[path.index(target) :] + [target]
                edges = [
                    f"{_where(modules, a, graph[a][b])}: {a} -> {b}" for a, b in zip(loop, loop[1:])
                ]
                cycles.append("\n  ".join(edges))
            elif target not in state:
                visit(target)
        path.pop()
        state[name] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name)
    assert not cycles, "import cycles:\n  " + "\n\n  ".join(cycles)


def test_only_the_entry_points_import_the_command_line():
    modules, graph = _graph()
    inside = lambda name: name == CLI or name.startswith(CLI + ".")  # noqa: E731
    offenders = [
        f"{_where(modules, name, line)}: {name} imports {target}"
        for name, targets in graph.items()
        if not inside(name) and name not in CLI_IMPORTERS
        for target, line in targets.items()
        if inside(target)
    ]
    assert not offenders, "the command line is imported from outside it:\n" + "\n".join(offenders)


def test_the_architecture_page_shows_the_same_layers():
    text = (ROOT.parent / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    rows = [line.split("|") for line in section.splitlines() if re.match(r"\| \d+ \|", line)]
    documented = [
        (
            cells[2].strip(),
            tuple(name.replace("/", ".") for name in re.findall(r"`([^`]+)`", cells[3])),
        )
        for cells in rows
    ]
    assert documented == LAYERS, f"docs/ARCHITECTURE.md lists\n{documented}\nthe test\n{LAYERS}"


def test_the_checker_sees_every_kind_of_import(tmp_path, monkeypatch):
    """The parser itself: relative, absolute, function-level and package-init imports count."""
    package = tmp_path / PACKAGE
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "_a.py").write_text("def f():\n    from .sub import _b\n")
    (package / "sub" / "__init__.py").write_text("from ._b import g as g\n")
    (package / "sub" / "_b.py").write_text(f"import {PACKAGE}._a\nfrom .. import _a\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", package)
    modules, graph = _graph()
    assert graph[f"{PACKAGE}._a"] == {f"{PACKAGE}.sub._b": 2, f"{PACKAGE}.sub": 2}
    assert graph[f"{PACKAGE}.sub._b"] == {f"{PACKAGE}._a": 1}
    assert graph[f"{PACKAGE}.sub"] == {f"{PACKAGE}.sub._b": 1}


# The experiments show what a user can do, so they use the public names. The one exception
# profiles the stages themselves (their tables, plan and state), which no user calls.
INTERNAL_EXPERIMENTS = {
    "compile_profile.py": "compiles each stage of C-DOG's plan on its own",
    "suite_census.py": "tallies the package's stored programs that each test meets",
    "memory_estimate.py": "reads XLA's memory figure of the program a library call compiles",
    "bench_live.py": "times each compiled program of a live frame where the frame calls it",
}


def private_imports(source: str) -> list[str]:
    """Every ``cdog_jax`` import of ``source`` that names a private module or name
    (a part starting with ``_``), as ``"line: module.name"``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == PACKAGE:
            for alias in node.names:
                parts = [*node.module.split("."), alias.name]
                if any(p.startswith("_") for p in parts):
                    found.append(f"{node.lineno}: {node.module}.{alias.name}")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == PACKAGE and any(p.startswith("_") for p in parts):
                    found.append(f"{node.lineno}: {alias.name}")
    return found


def test_experiments_import_only_public_names():
    experiments = ROOT.parent / "experiments"
    found = {
        str(path.relative_to(experiments)): problems
        for path in sorted(experiments.rglob("*.py"))
        if path.name not in INTERNAL_EXPERIMENTS
        and (problems := private_imports(path.read_text(encoding="utf-8")))
    }
    assert found == {}
    for name in INTERNAL_EXPERIMENTS:  # the exceptions exist and still need it
        assert private_imports((experiments / name).read_text(encoding="utf-8"))


def test_private_imports_are_found():
    source = (
        "from cdog_jax import associate\nfrom cdog_jax.metrics import _scores\n"
        "import cdog_jax._status\nfrom cdog_jax.people import _persons as p\n"
        "from numpy import _core\n"
    )
    assert private_imports(source) == [
        "2: cdog_jax.metrics._scores",
        "3: cdog_jax._status",
        "4: cdog_jax.people._persons",
    ]
