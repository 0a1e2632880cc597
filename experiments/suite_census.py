"""Where does the test suite's time go? A pytest plugin and its report.

Question: the suite spends most of its time compiling (``experiments/RESULTS.md``), but
compiling what? The big programs of the pipeline and the sweep, or the single operations
that JAX compiles one by one when a test calls a function outside ``jit``? And how much goes
to tracing and lowering, which the persistent compilation cache does not skip?

Method: JAX reports every trace, lowering and backend compilation (a persistent-cache hit
included) with its duration and program name through ``jax.monitoring``; the plugin adds
them up per test, next to the test's wall time, and each pytest process (each xdist
worker) writes one JSON file. A compilation under 0.1 s counts as *small* (single
operations, and small helpers), the others as *programs*. Summed over the workers, the
worker seconds are about twice the wall time of a run on two workers.

Usage::

    PYTHONPATH=experiments SUITE_CENSUS_OUT=/tmp/census python -m pytest -p suite_census
    python experiments/suite_census.py /tmp/census [--top 25] [--programs 30]
"""

from __future__ import annotations

import argparse
import collections
import json
import os
from pathlib import Path

SMALL_S = 0.1  # a compilation under this many seconds is "small"
_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "compile",
}

_current = ["<collection>"]
_tests: dict = collections.defaultdict(lambda: collections.defaultdict(float))
_programs: list = []  # (test, program name, seconds) of every program compilation
_stored: list = []  # (test, the stored program's function, method and argument shapes)


def _record(event: str, seconds: float, **kwargs) -> None:
    kind = _EVENTS.get(event)
    if kind is None:
        return
    row = _tests[_current[0]]
    if kind == "compile":
        size = "small" if seconds < SMALL_S else "program"
        row[f"compile_{size}_s"] += seconds
        row[f"compile_{size}_n"] += 1
        if size == "program":
            _programs.append((_current[0], str(kwargs.get("fun_name", "?")), seconds))
    else:
        row[f"{kind}_s"] += seconds
        row[f"{kind}_n"] += 1


def pytest_configure(config) -> None:
    import jax

    jax.monitoring.register_event_duration_secs_listener(_record)
    _tally_stored_programs()


def _tally_stored_programs() -> None:
    """Record which of the package's stored programs (one per function, method and argument
    shapes: ``cdog_jax/_runtime/stored_programs.py``) each test meets first in its process."""
    from cdog_jax._runtime import stored_programs

    load_or_export = stored_programs._load_or_export

    def tallied(path, fun, static, treedef, specs):
        shapes = " ".join("x".join(map(str, spec.shape)) or "()" for spec in specs[:6])
        described = f"{fun.__qualname__} {static.get('method', '')!r} {shapes}"
        _stored.append((_current[0], described))
        return load_or_export(path, fun, static, treedef, specs)

    stored_programs._load_or_export = tallied


try:
    import pytest

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        import time

        _current[0] = item.nodeid
        start = time.perf_counter()
        yield
        _tests[item.nodeid]["wall_s"] += time.perf_counter() - start
        _current[0] = "<between tests>"
except ImportError:  # the report needs no pytest
    pass


def pytest_sessionfinish(session) -> None:
    folder = Path(os.environ.get("SUITE_CENSUS_OUT", "suite_census"))
    folder.mkdir(parents=True, exist_ok=True)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    (folder / f"{worker}.json").write_text(json.dumps({k: dict(v) for k, v in _tests.items()}))
    (folder / f"{worker}.programs").write_text(json.dumps(_programs))
    (folder / f"{worker}.stored").write_text(json.dumps(_stored))


COLUMNS = ("wall_s", "compile_program_s", "compile_small_s", "trace_s", "lower_s")


def summarise(folder: str | Path) -> tuple[dict, dict]:
    """``(totals, per_file)`` over every JSON file in ``folder``: seconds and counts per
    column, and ``rest_s`` = wall less compilation, tracing and lowering (running the
    programs, NumPy oracles, child processes, Python)."""
    totals: dict = collections.defaultdict(float)
    per_file: dict = collections.defaultdict(lambda: collections.defaultdict(float))
    for path in sorted(Path(folder).glob("*.json")):
        for test, row in json.loads(path.read_text()).items():
            name = test.split("::")[0]
            for key, value in row.items():
                totals[key] += value
                per_file[name][key] += value
    for row in (totals, *per_file.values()):
        row["rest_s"] = row["wall_s"] - sum(row[c] for c in COLUMNS[1:])
    return totals, per_file


def programs_by_name(folder: str | Path) -> list[tuple[str, int, float, int]]:
    """``(program name, compilations, seconds, test files)`` over every worker's
    ``.programs`` file, most seconds first: which functions are compiled again and again
    (for new shapes or options) and by how many test files."""
    rows: dict = collections.defaultdict(lambda: [0, 0.0, set()])
    for path in sorted(Path(folder).glob("*.programs")):
        for test, name, seconds in json.loads(path.read_text()):
            row = rows[name]
            row[0] += 1
            row[1] += seconds
            row[2].add(test.split("::")[0])
    return sorted(
        ((name, n, s, len(files)) for name, (n, s, files) in rows.items()), key=lambda r: -r[2]
    )


def stored_program_files(folder: str | Path) -> tuple[int, int]:
    """``(distinct, in one file)`` over every worker's ``.stored`` file: how many distinct
    stored programs (function, method, shapes) the tests meet, and how many of them only
    one test file meets (a program that no other file shares is compiled for that file)."""
    files: dict = collections.defaultdict(set)
    for path in sorted(Path(folder).glob("*.stored")):
        for test, described in json.loads(path.read_text()):
            files[described].add(test.split("::")[0])
    return len(files), sum(len(f) == 1 for f in files.values())


def _line(name: str, row: dict) -> str:
    cells = [f"{row[c]:.0f}" for c in (*COLUMNS, "rest_s")]
    return (
        f"| {name} | "
        + " | ".join(cells)
        + f" | {row['compile_small_n']:.0f} | {row['compile_program_n']:.0f} |"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", help="the SUITE_CENSUS_OUT folder of a run")
    parser.add_argument("--top", type=int, default=25, help="test files to list, by wall time")
    parser.add_argument(
        "--programs", type=int, default=0, help="also list this many programs, by compile time"
    )
    args = parser.parse_args(argv)
    totals, per_file = summarise(args.folder)
    if not per_file:
        raise SystemExit(f"suite_census: no census files in {args.folder}")
    print("worker seconds, summed over the workers")
    print(
        "| | wall | compile: programs | compile: small | trace | lower | rest | small compiles | program compiles |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    print(_line("all tests", totals))
    for name, row in sorted(per_file.items(), key=lambda item: -item[1]["wall_s"])[: args.top]:
        print(_line(name, row))
    if args.programs:
        print("\nprograms compiled (>= 0.1 s), by compile seconds over the workers")
        print("| program | compilations | seconds | test files |")
        print("|---|---|---|---|")
        for name, n, seconds, files in programs_by_name(args.folder)[: args.programs]:
            print(f"| {name} | {n} | {seconds:.0f} | {files} |")
    distinct, alone = stored_program_files(args.folder)
    if distinct:
        print(
            f"\nstored programs (function, method, shapes): {distinct} distinct, "
            f"{alone} of them met by one test file only"
        )


if __name__ == "__main__":
    main()
