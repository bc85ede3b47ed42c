"""``exo-ilc simulate`` computes the therapy metrics of its trials (required torque, SPARC ...)
only when asked (``--metrics``; a ``--patient`` session always does), and then the numbers are
those of :func:`config_metrics` on the run's own trials."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.programs.metrics import config_metrics


def _simulate_json(tmp_path: Path, *extra: str) -> dict:
    out = tmp_path / f"run{len(extra)}.json"
    assert main(["simulate", "--trials", "2", "--mass-uncertainty", "0.1", "--quiet",
                 "--json", str(out), *extra]) == 0
    return json.loads(out.read_text())


def test_metrics_only_when_asked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plain = _simulate_json(tmp_path)
    asked = _simulate_json(tmp_path, "--metrics")
    capsys.readouterr()
    assert "metrics" not in plain["runs"][0]
    config = load_config(None)
    records = run_trials(config, 0.1, 2).records
    expected = [config_metrics(r, config.with_mass_uncertainty(0.1)).to_json() for r in records]
    assert [m["trial"] for m in asked["runs"][0]["metrics"]] == [1, 2]
    assert asked["runs"][0]["metrics"] == json.loads(json.dumps(expected))
    # everything else of the JSON is the same with or without the metrics
    del asked["runs"][0]["metrics"]
    assert asked == plain
