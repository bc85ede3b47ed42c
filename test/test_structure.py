"""The package's shape, read with ``ast``: no module over 600 lines, and no new function over 10
parameters (kernels take grouped arguments, as ``ArmModel.kernel_args``)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "exo_ilc_ros"
MAX_LINES = 600
MAX_PARAMETERS = 10

WIDE_TODAY = {
    "core/loop/trial.py:record_from_samples",
    "core/loop/wire_input.py:validate_feedforward",
    "core/learning/norm_optimal_recursive.py:solve_constrained_banded",
    "core/session/learning_session.py:run_trials",
    "wire/protocol.py:summary_values",
}
"""The functions over 10 parameters, each saying why in its docstring ("Over 10 parameters
because ..."; :func:`test_the_wide_functions_say_why`). The kernels take grouped arguments
(``PlantIntegration``, ``PatientTrial``, ``Controller``). The list may only shrink."""


def parameter_count(function: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Every parameter a caller may pass (``self``/``cls`` of a method not counted)."""
    args = function.args
    names = [*args.posonlyargs, *args.args, *args.kwonlyargs]
    count = len(names) + (args.vararg is not None) + (args.kwarg is not None)
    if names and names[0].arg in ("self", "cls"):
        count -= 1
    return count


def wide_functions(root: Path = PACKAGE) -> dict[str, int]:
    """``module:function`` -> parameters, for every function over :data:`MAX_PARAMETERS`."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                count = parameter_count(node)
                if count > MAX_PARAMETERS:
                    out[f"{path.relative_to(root).as_posix()}:{node.name}"] = count
    return out


def test_parameter_count_by_hand(tmp_path: Path) -> None:
    (tmp_path / "m.py").write_text(
        "def wide(a, b, c, d, e, f, g, h, i, j, k): pass\n"
        "def narrow(a, b, c, d, e, f, g, h, i, j): pass\n"
        "class C:\n"
        "    def method(self, a, b, c, d, e, f, g, h, i, j): pass\n"
        "    def starred(self, a, *rest, b, c, d, e, f, g, h, i, **more): pass\n")
    assert wide_functions(tmp_path) == {"m.py:wide": 11, "m.py:starred": 11}


def test_no_new_function_over_ten_parameters() -> None:
    found = wide_functions()
    new = {name: count for name, count in found.items() if name not in WIDE_TODAY}
    assert new == {}, "functions over 10 parameters (group the arrays): " + ", ".join(
        f"{name} ({count})" for name, count in sorted(new.items()))
    gone = WIDE_TODAY - set(found)
    assert gone == set(), f"no longer over 10 parameters: take them out of WIDE_TODAY: {gone}"


def test_the_wide_functions_say_why() -> None:
    docs = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                docs[f"{path.relative_to(PACKAGE).as_posix()}:{node.name}"] = \
                    ast.get_docstring(node) or ""
    silent = {name for name in WIDE_TODAY
              if "Over 10 parameters because" not in " ".join(docs[name].split())}
    assert silent == set(), f"say why in the docstring: {sorted(silent)}"


def test_no_module_over_600_lines() -> None:
    long = {path.relative_to(PACKAGE).as_posix(): n for path in PACKAGE.rglob("*.py")
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert long == {}, f"modules over {MAX_LINES} lines: {long}"
