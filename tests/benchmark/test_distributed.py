"""The sweep across two processes (``jax.distributed`` on localhost, CPU, Gloo collectives)
gives the same per-scene results as one process: the multi-host recipe of the README."""

import os
import socket
import subprocess
import sys
import textwrap

import numpy as np

_CHILD = textwrap.dedent(
    """
    import sys
    import numpy as np
    import jax
    process, processes, port, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
    if processes > 1:
        jax.distributed.initialize(coordinator_address=f"127.0.0.1:{port}", num_processes=processes, process_id=process)
    from cdog_jax.benchmark import Grid, sweep
    from cdog_jax.synthetic import default_rig
    result = sweep(default_rig(), Grid(sigmas=(0.0, 2.0), counts=(3, 9), seed=4), buckets=(10,), timing=False)
    assert result.num_devices == processes == jax.process_count(), (result.num_devices, jax.process_count())
    np.savez(out, **{k: np.asarray(v) for k, v in result.metrics["paper"].items()})
    """
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_processes_match_one(tmp_path):
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    port = str(_free_port())
    outs = [tmp_path / f"two_{i}.npz" for i in range(2)]
    children = [
        subprocess.Popen(
            [sys.executable, "-c", _CHILD, str(i), "2", port, str(outs[i])],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for i in range(2)
    ]
    logs = [child.communicate(timeout=600)[0] for child in children]
    for child, log in zip(children, logs):
        assert child.returncode == 0, log[-3000:]
    one = tmp_path / "one.npz"
    subprocess.run(
        [sys.executable, "-c", _CHILD, "0", "1", "0", str(one)], env=env, check=True, timeout=600
    )
    single = np.load(one)
    assert set(single.files) >= {"pg_f1", "g_f1", "num_groups"}
    for out in outs:  # every process holds the whole result
        got = np.load(out)
        for name in single.files:
            np.testing.assert_array_equal(got[name], single[name], err_msg=name)
