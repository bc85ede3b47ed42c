"""Keep numba's on-disk cache coherent across the kernel modules.

numba keys a cached function on its own file only, so a kernel that calls a kernel of another
module stays stale when only the callee changes. Unless ``NUMBA_CACHE_DIR`` is set, the cache
goes to a directory named by a hash of every kernel module's source.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

import numba

KERNEL_MODULES = ("arm/dynamics.py", "arm/joint_forces.py", "loop/plant.py", "loop/controller.py",
                  "loop/trial.py", "loop/patient.py", "loop/hold.py", "loop/observer.py",
                  "learning/norm_optimal_model.py", "learning/norm_optimal_qp.py",
                  "learning/norm_optimal_recursive.py", "learning/joint_force_regressors.py",
                  "person/neural_drive.py", "person/strapped.py")

if not os.environ.get("NUMBA_CACHE_DIR"):
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256(numba.__version__.encode())
    for name in KERNEL_MODULES:
        digest.update((here / name).read_bytes())
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    if not os.access(root.parent if not root.exists() else root, os.W_OK):
        root = Path(tempfile.gettempdir())
    numba.config.CACHE_DIR = str(root / "exo_ilc_ros" / "numba" / digest.hexdigest()[:16])
