"""The face ``exo_ilc_ros.core`` stays lazy at run time (PEP 562) and is typed for mypy and
editors: its ``if TYPE_CHECKING:`` imports name exactly the table ``_WHERE`` the run-time
``__getattr__`` loads from."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import exo_ilc_ros.core as core

ROOT = Path(core.__file__).resolve().parents[2]


def _type_checking_imports() -> dict[str, str]:
    """{name: module} of the ``if TYPE_CHECKING:`` block of core/__init__.py."""
    tree = ast.parse(Path(core.__file__).read_text())
    found: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING":
            for stmt in node.body:
                assert isinstance(stmt, ast.ImportFrom)
                for alias in stmt.names:
                    assert alias.asname == alias.name  # `X as X`: an explicit re-export
                    found[alias.name] = "." * stmt.level + (stmt.module or "")
    return found


def test_type_checking_imports_are_the_table() -> None:
    assert _type_checking_imports() == core._WHERE


def test_mypy_sees_run_trials_as_a_function(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text("from exo_ilc_ros.core import Config, run_trials\n"
                     "reveal_type(run_trials)\nreveal_type(Config)\n")
    env = {**os.environ, "MYPYPATH": str(ROOT)}
    # The package from MYPYPATH, nothing from site-packages (numpy's and the others' stubs are
    # Any): what the face shows is ours, and mypy takes a fifth of the time (12 s, not 60 s,
    # on a loaded machine).
    done = subprocess.run([sys.executable, "-m", "mypy", "--no-error-summary",
                           "--ignore-missing-imports", "--no-site-packages", "--cache-dir",
                           str(tmp_path / "cache"), str(probe)], capture_output=True, text=True,
                          cwd=tmp_path, env=env)
    revealed = [line.split("Revealed type is ", 1)[1] for line in done.stdout.splitlines()
                if "Revealed type is" in line]
    assert len(revealed) == 2, done.stdout + done.stderr
    assert revealed[0].startswith('"def (config: exo_ilc_ros.core.params.config.Config'), \
        revealed[0]
    assert "-> exo_ilc_ros.core.session.result.RunResult" in revealed[0], revealed[0]
    assert revealed[1].startswith('"def (') and revealed[1] != '"Any"', revealed[1]


def test_import_of_the_face_loads_nothing_heavy() -> None:
    heavy = ("numba", "scipy", "exo_ilc_ros.core.session.learning_session")
    done = subprocess.run(
        [sys.executable, "-c", "import sys, exo_ilc_ros.core as c; "
         f"print([m for m in {heavy!r} if m in sys.modules]); c.run_trials; "
         f"print([m for m in {heavy!r} if m in sys.modules])"],
        capture_output=True, text=True, check=True)
    before, after = done.stdout.splitlines()
    assert before == "[]"
    assert "'exo_ilc_ros.core.session.learning_session'" in after  # loaded on first use
