"""``import cdog_jax`` loads what associating needs and nothing more: the figures, the file
formats, the benchmark, calibration (and optimistix), the command line and matplotlib load
on first use. The command line itself loads the file formats, not the sweep or the figures."""

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

_CHILD = """
import json, sys
import cdog_jax
before = sorted(sys.modules)
import cdog_jax.cli
cli = sorted(sys.modules)
figure = cdog_jax.plot_rig
import cdog_jax.benchmark
sweep = cdog_jax.benchmark.sweep
print(json.dumps({"before": before, "cli": cli, "after": sorted(sys.modules), "figure": f"{figure.__module__}.{figure.__name__}",
                  "listed": "plot_association" in dir(cdog_jax), "sweep": f"{sweep.__module__}.{sweep.__name__}",
                  "sweep_listed": "sweep" in dir(cdog_jax.benchmark) and "sweep" in cdog_jax.benchmark.__all__}))
"""
LATER = (
    "cdog_jax.io",
    "cdog_jax.viz",
    "cdog_jax.benchmark",
    "cdog_jax.calibration",
    "cdog_jax.cli",
    "cdog_jax.synthetic",
    "matplotlib",
    "optimistix",
)


@pytest.fixture(scope="module")
def loaded():
    """The modules a fresh process holds after each step of ``_CHILD``, and what it found."""
    done = subprocess.run(
        [sys.executable, "-c", _CHILD], capture_output=True, text=True, check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_import_leaves_figures_formats_and_tools_for_later(loaded):
    early = [
        m
        for m in loaded["before"]
        if m.split(".")[0] in ("matplotlib", "optimistix") or m.startswith(LATER)
    ]
    assert early == [], f"import cdog_jax loaded {early}"
    assert "cdog_jax._associate" in loaded["before"] and "cdog_jax.baselines" in loaded["before"]
    # The figures are still where users find them, and load when asked for.
    assert loaded["figure"] == "cdog_jax.viz._rig_plot.plot_rig" and loaded["listed"]
    assert "cdog_jax.viz" in loaded["after"]


def test_the_command_line_leaves_the_sweep_and_the_figures_for_later(loaded):
    early = [
        m
        for m in loaded["cli"]
        if m.split(".")[0] == "matplotlib"
        or m.startswith(
            (
                "cdog_jax.viz",
                "cdog_jax.benchmark._sweep",
                "cdog_jax.benchmark._grid",
                "cdog_jax.calibration",
            )
        )
    ]
    assert early == [], f"import cdog_jax.cli loaded {early}"
    assert (
        "cdog_jax.io._rig_files" in loaded["cli"] and "cdog_jax.benchmark._methods" in loaded["cli"]
    )
    assert loaded["sweep"] == "cdog_jax.benchmark._sweep.sweep" and loaded["sweep_listed"]


def test_an_unknown_name_is_an_attribute_error():
    import cdog_jax

    with pytest.raises(AttributeError, match="has no attribute 'plot_everything'"):
        cdog_jax.plot_everything  # noqa: B018


def test_a_star_import_still_brings_the_figures():
    names = {}
    exec("from cdog_jax import *", names)
    assert {"associate", "Config", "plot_rig", "plot_association"} <= set(names)


def _function_level_imports():
    """``(file, line, module, commented)`` of every import inside a function of the package:
    ``module`` as it would be loaded (a relative import resolved; ``from pkg import sub`` of a
    subpackage is ``pkg.sub``, of a name ``pkg``); ``commented``: a comment on the import's
    block (consecutive imports, blank lines between them allowed) on or above its first line."""
    import cdog_jax

    root = Path(cdog_jax.__file__).parent
    found = []
    for path in sorted(root.rglob("*.py")):
        lines = path.read_text().splitlines()
        # The package a relative import starts from: the module's own (a package's for
        # its __init__).
        package = path.relative_to(root.parent).with_suffix("").parts[:-1]
        for function in ast.walk(ast.parse("\n".join(lines))):
            if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            previous_end, commented = None, False
            for node in ast.walk(function):
                if not isinstance(node, (ast.Import, ast.ImportFrom)):
                    continue
                if isinstance(node, ast.Import):
                    modules = [alias.name for alias in node.names]
                else:
                    base = ".".join(package[: len(package) - node.level + 1]) if node.level else ""
                    module = ".".join(p for p in (base, node.module or "") if p)
                    modules = (
                        [module]
                        if node.module
                        else [
                            f"{module}.{a.name}"
                            if _is_module(root, f"{module}.{a.name}")
                            else module
                            for a in node.names
                        ]
                    )
                between = lines[previous_end : node.lineno - 1] if previous_end else [None]
                if not all(line is not None and line.strip() == "" for line in between):
                    commented = (
                        lines[node.lineno - 2].strip().startswith("#")
                        or "#" in lines[node.lineno - 1]
                    )
                previous_end = node.end_lineno
                for module in modules:
                    found.append((path.relative_to(root.parent), node.lineno, module, commented))
    return found


def _is_module(root: Path, name: str) -> bool:
    """Whether ``name`` (dotted, from the package's parent folder) is a module or package."""
    path = root.parent.joinpath(*name.split("."))
    return path.with_suffix(".py").exists() or (path / "__init__.py").exists()


def test_imports_inside_functions_defer_what_the_package_does_not_load(loaded):
    """An import inside a function is there to defer a module that ``import cdog_jax`` and
    its command line do not load (matplotlib, scipy, tqdm, the synthetic scenes, the sweep,
    an optional library), and says so in a comment; any other import goes at the top of its
    module."""
    early = set(loaded["cli"])
    found = _function_level_imports()
    assert len(found) > 10  # the figures' and the optional libraries' imports at least
    needless = [f"{f}:{line} {m}" for f, line, m, _ in found if m in early]
    assert needless == [], "imports inside functions of modules already loaded"
    silent = [f"{f}:{line} {m}" for f, line, m, commented in found if not commented]
    assert silent == [], "imports inside functions without a comment saying why"
