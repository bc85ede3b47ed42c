"""The graph's ROS domain (issue 36, point 11): a :class:`GraphSession` without a domain id
takes an exported ``ROS_DOMAIN_ID`` (as ``exo-ilc run`` does), so benches and tests that start
graphs stay in the domain their user chose; without one it claims a free one; a value that is
no domain id is a ConfigError naming the variable. No process is started."""

from __future__ import annotations

import pytest

from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.orchestration.graph import GraphSession
from exo_ilc_ros.orchestration.launcher import DOMAIN_IDS, exported_domain_id


def _domain_of(domain_id: int | None = None) -> int:
    session = GraphSession(load_config(), domain_id)
    try:
        assert session.env["ROS_DOMAIN_ID"] == str(session.domain_id)
        return session.domain_id
    finally:
        session.close()


def test_an_exported_domain_id_is_the_graphs(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "142")  # outside the claimed 1-100: not a coincidence
    assert _domain_of() == 142
    assert _domain_of(7) == 7  # a given one wins


def test_without_one_a_free_domain_is_claimed(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    assert _domain_of() in DOMAIN_IDS
    monkeypatch.setenv("ROS_DOMAIN_ID", " ")
    assert exported_domain_id() is None


@pytest.mark.parametrize("value", ["abc", "-1", "233", "4.5"])
def test_an_exported_value_that_is_no_domain_id_is_refused(
        value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", value)
    with pytest.raises(ConfigError) as error:
        GraphSession(load_config())
    assert error.value.key == "ROS_DOMAIN_ID" and repr(value) in str(error.value)
