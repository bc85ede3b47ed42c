"""The graph's ROS domain (issue 36, point 11): an exported ``ROS_DOMAIN_ID`` is honoured by
``exo-ilc run``/``paper`` and the benches (:func:`exported_domain_id`, passed to
:class:`GraphSession`); a value that is no domain id is a ConfigError naming the variable.
A GraphSession given no id claims a free domain of its own: the test suite exports its own
domain for its in-process nodes, and a graph on it was heard by the next test's (test_hostile's
exact message counts on /feedforward). No process is started here."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.orchestration.graph import GraphSession
from exo_ilc_ros.orchestration.launcher import DOMAIN_IDS, exported_domain_id

ROOT = Path(__file__).resolve().parents[1]


def _domain_of(domain_id: int | None = None) -> int:
    session = GraphSession(load_config(), domain_id)
    try:
        assert session.env["ROS_DOMAIN_ID"] == str(session.domain_id)
        return session.domain_id
    finally:
        session.close()


def test_an_exported_domain_id_is_the_graphs(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "142")  # outside the claimed 1-100: not a coincidence
    assert exported_domain_id() == 142 and _domain_of(exported_domain_id()) == 142
    assert _domain_of() in DOMAIN_IDS  # no id given: a free one of its own
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert exported_domain_id() is None
    monkeypatch.setenv("ROS_DOMAIN_ID", " ")
    assert exported_domain_id() is None


@pytest.mark.parametrize("value", ["abc", "-1", "233", "4.5"])
def test_an_exported_value_that_is_no_domain_id_is_refused(
        value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", value)
    with pytest.raises(ConfigError) as error:
        exported_domain_id()
    assert error.value.key == "ROS_DOMAIN_ID" and repr(value) in str(error.value)


def test_every_bench_that_starts_a_graph_honours_the_exported_domain() -> None:
    """Each GraphSession(...) and run_graph(...) call of bench/ passes the exported domain."""
    calls = []
    for path in sorted((ROOT / "bench").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) in (
                    "GraphSession", "run_graph"):
                calls.append((path.name, node.lineno, ast.unparse(node.args[1])
                              if len(node.args) > 1 else None))
    assert len(calls) >= 5
    assert all(arg == "exported_domain_id()" for _, _, arg in calls), calls
