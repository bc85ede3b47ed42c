"""What a new user hit in the graph (issue 25): a live `param set` during `exo-ilc run` shown in
its output, its JSON and `analyze --json`, with the trial it took effect; a mistyped node that
fails fast listing the running ones; an exported ROS_DOMAIN_ID honoured; a therapy session
through the graph that prints its therapy metrics and names its bag like the in-process ones."""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from exo_ilc_ros.orchestration.launcher import claim_domain_id

pytestmark = pytest.mark.graph

SHORT = '"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'


def _exo_ilc(*args: str, **kwargs: Any) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", *args], text=True,
                          capture_output=True, stdin=subprocess.DEVNULL, check=False, **kwargs)


def _read_until(process: subprocess.Popen[str], text: str, timeout: float) -> str:
    """stderr of ``process`` up to the line holding ``text``."""
    assert process.stderr is not None
    seen = ""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and text not in seen:
        ready, _, _ = select.select([process.stderr], [], [], 0.5)
        if ready:
            line = process.stderr.readline()
            if not line and process.poll() is not None:
                break
            seen += line
    assert text in seen, seen[-3000:]
    return seen


def test_live_change_shows_in_run_and_analyze_and_a_mistyped_node_fails_fast(
        tmp_path: Path) -> None:
    (tmp_path / "short.yaml").write_text(SHORT)
    claim = claim_domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(claim.domain_id))  # exported, no --domain-id
    out = tmp_path / "run.json"
    run = subprocess.Popen(
        [sys.executable, "-m", "exo_ilc_ros.cli.main", "run", "--config", "short.yaml",
         "--trials", "300", "--no-store", "--quiet", "--json", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, env=env,
        text=True, cwd=tmp_path)
    try:
        err = _read_until(run, "graph on ROS_DOMAIN_ID=", 120.0)
        assert f"graph on ROS_DOMAIN_ID={claim.domain_id} " in err  # honoured, not replaced
        typo = subprocess.Popen(
            [sys.executable, "-m", "exo_ilc_ros.cli.main", "param", "set", "ilc_supervisr",
             "law", "linear", "--timeout", "120"], stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, env=env, text=True)
        change = _exo_ilc("param", "set", "ilc_supervisor", "law", "linear", "--timeout",
                          "120", env=env, timeout=150)  # the graph may still be starting
        assert change.returncode == 0, change.stderr
        _, typo_err = typo.communicate(timeout=150)
        assert typo.returncode == 2, typo_err
        assert "no node ilc_supervisr" in typo_err and "did you mean ilc_supervisor?" in typo_err
        listed = typo_err.partition("Running nodes:")[2]
        # the nodes DDS discovery had seen by then (which ones is a race on a loaded machine)
        assert any(node in listed for node in ("plant_simulator", "computed_torque_controller",
                                                "bag_recorder")), typo_err
        stdout, rest = run.communicate(timeout=600)
        assert run.returncode == 0, (err + rest)[-3000:]
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
        claim.release()
    document = json.loads(out.read_text())["runs"][0]
    change_at = document["live_changes"][0]["trial"]
    assert document["live_changes"][0]["parameter"] == "law"
    assert document["laws"] == [{"from_trial": 1, "law": "sign"},
                                {"from_trial": change_at, "law": "linear"}]
    assert f"live change from trial {change_at}: ilc_supervisor law = \"linear\"" in stdout
    assert "sign->linear" in stdout
    bag = document["bag"]
    analyzed = tmp_path / "a.json"
    result = _exo_ilc("analyze", bag, "--json", str(analyzed), "--quiet", timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    again = json.loads(analyzed.read_text())["runs"][0]
    assert again["live_changes"][0]["trial"] == change_at
    assert again["laws"][1] == {"from_trial": change_at, "law": "linear"}


def test_therapy_session_through_the_graph_prints_metrics_and_names_its_bag(
        tmp_path: Path) -> None:
    """`run --patient` prints the therapy metrics (simulate did, run did not) and its bag is
    ``graph_<patient>_<exercise>_*``: `report bags/*_p4_*` finds graph and in-process ones."""
    (tmp_path / "short.yaml").write_text(SHORT)
    result = _exo_ilc("run", "--config", "short.yaml", "--patient", "p4", "--new-patient",
                      "--exercise", "shoulder_abduction", "--trials", "2", "--profiles", "prof",
                      "--quiet", timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Therapy metrics: patient p4, exercise shoulder_abduction, 2 trials" in result.stdout
    assert ": B on shoulder_flexion not measurable" in result.stdout
    assert "paper joint 1" not in result.stdout
    bags = sorted(p.name for p in (tmp_path / "bags").iterdir())
    assert len(bags) == 1 and bags[0].startswith("graph_p4_shoulder_abduction_sign_d0.05_")
    report = _exo_ilc("report", *(str(p) for p in (tmp_path / "bags").glob("*_p4_*")),
                      "--html", "r.html", "--profiles", "prof", timeout=120, cwd=tmp_path)
    assert report.returncode == 0, report.stderr[-2000:]
    assert "shoulder_abduction" in (tmp_path / "r.html").read_text()
