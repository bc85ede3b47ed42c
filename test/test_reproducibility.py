"""The headline numbers do not depend on the machine (issue 25, shared/notes/reproducibility.md).

OpenBLAS picks its kernels by CPU (``OPENBLAS_CORETYPE`` overrides the choice; read when numpy is
imported, so each run is a process of its own). The quintic's coefficients came from a LAPACK
solve whose last bits, and the sign of a1 and a2 (exactly 0), depended on the kernel; the sign
law takes the sign of the error's acceleration at rest, so the runs diverged from trial 3 on.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from exo_ilc_ros.core.reference.trajectory import QuinticTrajectory

KERNELS = ("Haswell", "SkylakeX")


def _simulate(kernel: str, out: Path) -> bytes:
    env = {**os.environ, "OPENBLAS_CORETYPE": kernel}
    result = subprocess.run(
        [sys.executable, "-m", "exo_ilc_ros.cli.main", "simulate", "--mass-uncertainty", "0.05",
         "0.15", "--trials", "12", "--quiet", "--json", str(out)],
        env=env, capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL,
        check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    return out.read_bytes()


def test_simulate_json_is_the_same_bits_under_every_blas_kernel(tmp_path: Path) -> None:
    """The paper's experiment at 5 and 15 % (the full movement, the table's law), with the
    therapy metrics of every trial, byte for byte under two OpenBLAS kernels."""
    first, second = (_simulate(kernel, tmp_path / f"{kernel}.json") for kernel in KERNELS)
    assert first == second


def test_quintic_coefficients_are_exact() -> None:
    """a1 = a2 = 0 exactly, a3..a5 = 10, -15, 6 times d / T^n, eq (14): no rounding a kernel
    could flip."""
    traj = QuinticTrajectory.rest_to_rest([0.1, -0.2, 0.0], [1.1, 0.3, 0.0], 5.0)
    a = traj.coefficients
    assert np.all(a[1] == 0.0) and np.all(a[2] == 0.0)
    d = np.array([1.0, 0.5, 0.0])
    np.testing.assert_array_equal(a[3], 10.0 * d / 5.0**3)
    np.testing.assert_array_equal(a[5], 6.0 * d / 5.0**5)
    q, qd, qdd = traj.evaluate(np.array([0.0, 5.0]))
    np.testing.assert_allclose(q, [[0.1, -0.2, 0.0], [1.1, 0.3, 0.0]], atol=1e-15)
    assert np.all(qd[0] == 0.0) and np.all(qdd[0] == 0.0)
    np.testing.assert_allclose(qd[1], 0.0, atol=1e-15)
    np.testing.assert_allclose(qdd[1], 0.0, atol=1e-14)
