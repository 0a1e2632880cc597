"""What does the test run's compilation cache cost and save? Loaded by every Python process
whose ``PYTHONPATH`` holds this folder (the pytest workers and the command-line children
alike), when ``CACHE_CENSUS_OUT`` names a folder: each process then times JAX's cache
functions (keys, lookups, writes) and its backend compilations, adds up what JAX reports of
the cache's hits (the compile time they saved, net of reading them), and writes one line of
totals to that folder when it ends. ``python experiments/cache_census/report.py FOLDER``
sums them.

Usage (JAX's strict promotion set up front: this module imports JAX before the suite's
conftest sets it)::

    CACHE_CENSUS_OUT=/tmp/cache JAX_NUMPY_RANK_PROMOTION=raise JAX_NUMPY_DTYPE_PROMOTION=strict \\
        PYTHONPATH=experiments/cache_census python -m pytest
    python experiments/cache_census/report.py /tmp/cache
"""

import os

if os.environ.get("CACHE_CENSUS_OUT"):
    import atexit
    import collections
    import json
    import time

    import jax._src.compilation_cache as _cache
    import jax._src.compiler as _compiler
    from jax import monitoring

    _seconds: collections.Counter = collections.Counter()
    _calls: collections.Counter = collections.Counter()

    def _timed(module, name: str, tag: str) -> None:
        function = getattr(module, name)

        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                _seconds[tag] += time.perf_counter() - start
                _calls[tag] += 1

        setattr(module, name, timed)

    _timed(_compiler, "backend_compile_and_load", "compile")
    _timed(_compiler, "_cache_read", "lookup")
    _timed(_compiler, "_cache_write", "write")
    _timed(_cache, "get_cache_key", "key")

    def _listen(event: str, seconds: float, **_) -> None:
        tag = {
            "/jax/compilation_cache/compile_time_saved_sec": "saved by hits",
            "/jax/compilation_cache/cache_retrieval_time_sec": "reading hits",
        }.get(event)
        if tag:
            _seconds[tag] += seconds
            _calls[tag] += 1

    monitoring.register_event_duration_secs_listener(_listen)

    def _write() -> None:
        path = os.path.join(os.environ["CACHE_CENSUS_OUT"], f"{os.getpid()}.json")
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w") as f:
            json.dump({"seconds": dict(_seconds), "calls": dict(_calls)}, f)

    atexit.register(_write)
