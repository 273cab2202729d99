"""The BLAS code paths and thread counts the determinism checks compare, and a runner of Python
code in a fresh interpreter on one of them (shared by the tests that fit in subprocesses)."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

#: The reference: the default code paths of MKL and OpenBLAS, one thread.
REFERENCE = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
#: Everything changed at once: MKL's AVX2 code path, OpenBLAS's Haswell kernels, two threads.
EVERYTHING_ELSE = {
    "MKL_CBWR": "AVX2",
    "OPENBLAS_CORETYPE": "Haswell",
    "OMP_NUM_THREADS": "2",
    "MKL_NUM_THREADS": "2",
    "OPENBLAS_NUM_THREADS": "2",
}


def blas_env(env: dict[str, str]) -> dict[str, str]:
    """This process's environment without its BLAS / OpenMP settings, with ``env`` added."""
    full = {k: v for k, v in os.environ.items() if not k.startswith(("MKL_", "OPENBLAS_", "OMP_"))}
    full.update(env)
    return full


def run_python(script: str, env: dict[str, str], *, timeout: float = 600) -> str:
    """Standard output of ``python -c script`` in a fresh interpreter under ``env`` (added to a
    BLAS-free environment), run in an empty temporary folder; fails the test on an error."""
    with tempfile.TemporaryDirectory() as cwd:
        proc = subprocess.run(
            [sys.executable, "-c", script],
            env=blas_env(env),
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout
