"""Every bad command-line value of every ``exo-ilc`` sub-command is refused where it is given,
with a message naming the flag, the value and the rule, and no traceback (issue 18).

The checks run in-process (``main([...])``): a value that got past them would start the run,
so each case also checks that nothing was run (no trial simulated, no graph or ROS context
started, no worker pool made), by counting those calls, not by the time the command took.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.cli.param import ParamError, parse_value, unknown_parameter

SHIPPED = Path(__file__).resolve().parents[1] / "config" / "exo_ilc.yaml"

# (argv, what the message must contain: the flag, the value, the rule). "{tmp}" is a scratch
# directory, "{file}" an existing plain file in it, "{bad_trials}" a YAML with max_trials: "3".
CONFIG_FLAGS = [
    (["--trials", "0"], ["argument --trials", "0", "must be > 0", "max_trials"]),
    (["--trials", "-5"], ["argument --trials", "-5", "must be > 0"]),
    (["--trials", "abc"], ["argument --trials", "'abc'", "must be an integer"]),
    (["--trials", "2.5"], ["argument --trials", "2.5", "must be an integer"]),
    (["--mass-uncertainty", "-2"], ["argument --mass-uncertainty", "-2", "must be >= -0.9",
                                    "mass_uncertainty"]),
    (["--mass-uncertainty", "0.1", "nan"], ["argument --mass-uncertainty", "nan", "finite"]),
    (["--mass-uncertainty", "ten"], ["argument --mass-uncertainty", "'ten'", "must be a number"]),
    (["--config", "{tmp}/missing.yaml"], ["argument --config", "missing.yaml", "no such file"]),
    (["--config", "{tmp}"], ["argument --config", "{tmp}", "must be a file"]),
    (["--config", "{bad_trials}", "--trials", "3"], ["bad_trials.yaml", "max_trials",
                                                     "must be an integer", "'3'"]),
    (["--config", "{bad_yaml}"], ["bad_yaml.yaml", "invalid YAML"]),
    (["--config", "{binary}"], ["binary.yaml", "not a text (UTF-8) file"]),
    (["--config", "{bad_key}"], ["bad_key.yaml", "max_trial", "unknown parameter"]),
    (["--json", "{tmp}/no/such/dir/out.json"], ["argument --json", "out.json",
                                                "does not exist"]),
    (["--json", "{tmp}"], ["argument --json", "{tmp}", "directory"]),
]

CASES: list[tuple[list[str], list[str]]] = []
for command in ("simulate", "run"):
    CASES += [([command, *argv], expected) for argv, expected in CONFIG_FLAGS]
    CASES += [([command, "--law", "fast"], ["argument --law", "'fast'", "invalid choice"])]
CASES += [
    (["simulate", "--bag", "{file}"], ["argument --bag", "file.txt", "must be a directory"]),
    (["simulate", "--store", "{file}"], ["argument --store", "file.txt", "must be a directory"]),
    (["simulate", "--resume"], ["--resume", "--store"]),
    (["simulate", "--replay", "{tmp}/nobag"], ["--replay", "nobag"]),
    (["simulate", "--replay", "{tmp}/nobag", "--trials", "3"], ["--replay", "--trials"]),
    (["run", "--domain-id", "-1"], ["argument --domain-id", "-1", "from 0 to 232"]),
    (["run", "--domain-id", "300"], ["argument --domain-id", "300", "from 0 to 232"]),
    (["run", "--domain-id", "x"], ["argument --domain-id", "'x'", "must be an integer"]),
    (["run", "--bag-dir", "{file}"], ["argument --bag-dir", "file.txt", "must be a directory"]),
    (["run", "--store", "{file}"], ["argument --store", "file.txt", "must be a directory"]),
    (["run", "--no-store", "--store", "{tmp}/s"], ["--no-store", "cannot be combined"]),
    (["run", "--resume"], ["--resume", "needs --store"]),
    (["run", "--no-bag", "--bag-dir", "{tmp}"], ["--no-bag", "--bag-dir", "ignored"]),
    (["run", "--no-bag", "--isolated-recorder"], ["--no-bag", "--isolated-recorder"]),
    (["paper", "--in-process", "--domain-id", "5"], ["--in-process", "--domain-id", "ignored"]),
    (["compare", "--trials", "0"], ["argument --trials", "0", "must be > 0"]),
    (["compare", "--mass-uncertainty", "-2"], ["argument --mass-uncertainty", "-2",
                                               "must be >= -0.9"]),
    (["compare", "--jobs", "0"], ["argument --jobs", "0", ">= 1"]),
    (["compare", "--plot", "{tmp}/fig.xyz"], ["argument --plot", "fig.xyz", ".png"]),
    (["compare", "--plot", "{tmp}"], ["argument --plot", "directory"]),
    (["compare", "--tuned", "{tmp}/none.yaml"], ["argument --tuned", "none.yaml",
                                                 "no such file"]),
    (["compare", "--tuned", "{bad_level}", "--trials", "2"], ["bad_level.yaml",
                                                              "level_low", "must be >= 0"]),
    (["compare", "--config", "{tmp}/none.yaml"], ["argument --config", "no such file"]),
    (["compare", "--no-tuned", "--tuned", "{file}"], ["--no-tuned", "--tuned", "file.txt",
                                                      "cannot be combined"]),
    (["compare", "--json", "{tmp}/no/dir/x.json"], ["argument --json", "does not exist"]),
    (["compare", "--plot", "{tmp}/no/dir/x.png"], ["argument --plot", "does not exist"]),
    (["paper", "--trials", "0"], ["argument --trials", "0", "must be > 0"]),
    (["paper", "--domain-id", "300"], ["argument --domain-id", "300", "from 0 to 232"]),
    (["paper", "--plot", "{tmp}/fig.txt"], ["argument --plot", "fig.txt", ".png"]),
    (["paper", "--csv", "{tmp}/no/dir/t.csv"], ["argument --csv", "t.csv", "does not exist"]),
    (["paper", "--json", "{tmp}"], ["argument --json", "directory"]),
    (["paper", "--bag-dir", "{file}"], ["argument --bag-dir", "must be a directory"]),
    (["paper", "--config", "{tmp}/none.yaml"], ["argument --config", "no such file"]),
    (["paper", "--config", "{bad_trials}", "--trials", "3"], ["bad_trials.yaml", "max_trials"]),
    (["tune", "--mass-uncertainty", "-2"], ["argument --mass-uncertainty", "-2",
                                            "must be >= -0.9"]),
    (["tune", "--trials", "0"], ["argument --trials", "0", "must be > 0"]),
    (["tune", "--trials", "1"], ["argument --trials", "1", "must be >= 2"]),
    (["tune", "--budget", "-1"], ["argument --budget", "-1", ">= 0"]),
    (["tune", "--jobs", "0"], ["argument --jobs", "0", ">= 1"]),
    (["tune", "--peak-weight", "-1"], ["argument --peak-weight", "-1", ">= 0"]),
    (["tune", "--peak-weight", "inf"], ["argument --peak-weight", "inf", "finite"]),
    (["tune", "--seed", "-1"], ["argument --seed", "-1", "from 0 to"]),
    (["tune", "--aggregate", "median"], ["argument --aggregate", "'median'", "invalid choice"]),
    (["tune", "--out", "{tmp}/tuned.txt"], ["argument --out", "tuned.txt", ".yaml"]),
    (["tune", "--out", "{tmp}"], ["argument --out", "directory"]),
    (["tune", "--storage", "nosuchdb://u@h/db"], ["argument --storage", "nosuchdb",
                                                  "database URL"]),
    (["tune", "--storage", "mysql+mysqldb://u@h/db"], ["argument --storage", "mysqldb",
                                                       "not installed"]),
    (["tune", "--storage", "postgresql+psycopg2://me:secret@h/db"], [
        "argument --storage", "psycopg2", "not installed", "'postgresql+psycopg2://me:***@h/db'"]),
    (["tune", "--storage", "{file}/tune.journal"], ["argument --storage", "not a directory"]),
    (["tune", "--study-name", " "], ["argument --study-name", "must not be empty"]),
    (["tune", "--storage", "sqlite:///{tmp}/no/dir/t.db"], ["argument --storage", "t.db",
                                                            "does not exist"]),
    (["tune", "--config", "{tmp}/none.yaml"], ["argument --config", "no such file"]),
    (["analyze-loop", "--mass-uncertainty", "-2"], ["argument --mass-uncertainty", "-2",
                                                    "must be >= -0.9"]),
    (["analyze-loop", "--cutoff", "0"], ["argument --cutoff", "0", "must be > 0"]),
    (["analyze-loop", "--cutoff", "60"], ["argument --cutoff", "60", "Nyquist"]),
    (["analyze-loop", "--cutoff", "fast"], ["argument --cutoff", "'fast'", "must be a number"]),
    (["analyze-loop", "--lifted", "-1"], ["argument --lifted", "-1", ">= 0"]),
    (["analyze-loop", "--law", "x"], ["argument --law", "invalid choice"]),
    (["analyze-loop", "--plot", "{tmp}/f.doc"], ["argument --plot", "f.doc", ".png"]),
    (["analyze-loop", "--config", "{tmp}/none.yaml"], ["argument --config", "no such file"]),
    (["analyze", "{tmp}/nobag"], ["nobag"]),
    (["analyze", "{file}"], ["file.txt"]),
    (["analyze", "{tmp}", "--trial", "0"], ["argument --trial", "0", ">= 1"]),
    (["analyze", "{tmp}", "--trial", "x"], ["argument --trial", "'x'", "must be an integer"]),
    (["analyze", "{tmp}", "--plot", "{tmp}/f.txt"], ["argument --plot", "f.txt", ".png"]),
    (["analyze", "{tmp}", "--csv", "{tmp}"], ["argument --csv", "directory"]),
    (["analyze", "{tmp}", "--json", "{tmp}/no/dir/a.json"], ["argument --json",
                                                             "does not exist"]),
    (["analyze", "{tmp}", "--config-out", "{tmp}/no/dir/c.yaml"], ["argument --config-out",
                                                                   "does not exist"]),
    (["param", "set", "ilc_supervisor", "schedule.position.threshold_low", "[1.0, 2.0"],
     ["VALUE", "'[1.0, 2.0'", "not a valid YAML value"]),
    (["param", "set", "ilc_supervisor", "law", "{a: 1}"], ["VALUE", "{a: 1}", "mapping"]),
    (["param", "set", "ilc_supervisor", "law", "[1, [2]]"], ["VALUE", "[1, [2]]", "flat"]),
    (["param", "set", "ilc_supervisor", "law", "[1, true]"], ["VALUE", "[1, true]", "mixes"]),
    (["param", "set", "ilc_supervisor", "law", ""], ["VALUE", "''", "empty"]),
    (["param", "set", "ilc_supervisor", "law"], ["needs a VALUE"]),
    (["param", "get", "ilc_supervisor"], ["needs a parameter NAME"]),
    (["param", "get", "ilc_supervisor", "law", "sign"], ["takes no VALUE", "'sign'"]),
    (["param", "list", "ilc_supervisor", "law"], ["takes no NAME", "'law'"]),
    (["param", "list", "bad node!"], ["NODE", "'bad node!'", "not a valid node name"]),
    (["param", "frob", "ilc_supervisor"], ["argument action", "'frob'", "invalid choice"]),
    (["param", "list", "ilc_supervisor", "--timeout", "0"], ["argument --timeout", "0",
                                                             "must be > 0"]),
    (["param", "list", "ilc_supervisor", "--domain-id", "-3"], ["argument --domain-id", "-3"]),
    (["urdf", "--config", "{tmp}/none.yaml"], ["argument --config", "no such file"]),
    (["urdf", "--out", "{tmp}/no/dir/arm.urdf"], ["argument --out", "arm.urdf",
                                                  "does not exist"]),
    (["urdf", "--out", "{tmp}"], ["argument --out", "directory"]),
    (["study", "--trials", "0"], ["argument --trials", "0", "must be > 0"]),
    (["study", "--seeds", "0"], ["argument --seeds", "0", ">= 1"]),
    (["study", "--workers", "0"], ["argument --workers", "0", ">= 1"]),
    (["study", "--figure", "{tmp}/f.txt"], ["argument --figure", "f.txt", ".png"]),
    (["study", "--mass-uncertainty", "nan"], ["argument --mass-uncertainty", "nan", "finite"]),
    (["study", "--laws", "nonsense", "--trials", "3"], ["--laws", "unknown law 'nonsense'"]),
    (["study", "--laws", "{tmp}/none.yaml"], ["--laws", "no such config file"]),
    (["study", "--laws", "{bad_key}", "--trials", "3"], ["bad_key.yaml", "max_trial",
                                                         "unknown parameter"]),
    (["study", "--scenarios", "{tmp}/none.yaml"], ["none.yaml", "no such scenario file"]),
    (["study", "--scenarios", "nowhere"], ["unknown scenario 'nowhere'"]),
    (["frobnicate"], ["invalid choice", "'frobnicate'"]),
]


def _ids() -> list[str]:
    return [" ".join(argv)[:60] for argv, _ in CASES]


def _fill(text: str, scratch: dict[str, str]) -> str:
    for key, value in scratch.items():
        text = text.replace("{" + key + "}", value)
    return text


@pytest.fixture
def work_started(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The work a command started, as it starts it: a simulated trial (in-process, a person
    strapped in too), the graph's node processes, a ROS context (a graph run, a ``param``
    call), a worker pool (a study, a comparison). Each is recorded, then run as usual."""
    import concurrent.futures

    import rclpy

    from exo_ilc_ros.core.person.experiment import StrappedExperiment
    from exo_ilc_ros.core.sim.experiment import Experiment
    from exo_ilc_ros.orchestration.launcher import GraphProcesses

    started: list[str] = []

    def recording(owner: Any, name: str) -> None:
        original = getattr(owner, name)

        def wrapper(*args: Any, **kwargs: Any) -> Any:
            started.append(f"{getattr(owner, '__name__', owner)}.{name}")
            return original(*args, **kwargs)

        monkeypatch.setattr(owner, name, wrapper)

    for owner, name in ((Experiment, "run_trial"), (StrappedExperiment, "run_trial"),
                        (GraphProcesses, "start"), (rclpy, "init"),
                        (concurrent.futures.ProcessPoolExecutor, "__init__")):
        recording(owner, name)
    return started


@pytest.fixture
def scratch(tmp_path: Path) -> dict[str, str]:
    plain = tmp_path / "file.txt"
    plain.write_text("not a bag, not a directory\n")
    bad_trials = tmp_path / "bad_trials.yaml"
    bad_trials.write_text('ilc_supervisor:\n  ros__parameters:\n    max_trials: "3"\n')
    bad_yaml = tmp_path / "bad_yaml.yaml"
    bad_yaml.write_text("ilc_supervisor:\n  ros__parameters: [1, 2\n")
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(b"\x00\x01\xff")
    bad_key = tmp_path / "bad_key.yaml"
    bad_key.write_text("ilc_supervisor:\n  ros__parameters:\n    max_trial: 3\n")
    bad_level = tmp_path / "bad_level.yaml"
    bad_level.write_text("ilc_supervisor:\n  ros__parameters:\n    schedule:\n      position:\n"
                         "        level_low: [-1.0, 0.0, 0.0]\n")
    return {"tmp": str(tmp_path), "file": str(plain), "bad_trials": str(bad_trials),
            "bad_yaml": str(bad_yaml), "bad_level": str(bad_level), "binary": str(binary),
            "bad_key": str(bad_key)}


@pytest.mark.parametrize(("argv", "expected"), CASES, ids=_ids())
def test_bad_input_is_refused_with_flag_value_and_rule(
        argv: list[str], expected: list[str], scratch: dict[str, str],
        work_started: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    argv = [_fill(a, scratch) for a in argv]
    code = main(argv)  # argparse's exit is returned, not raised
    out, err = capsys.readouterr()
    text = out + err
    assert code == 2, text
    assert "Traceback" not in text and "internal error" not in text, text
    assert f"exo-ilc {argv[0]}" in err or "exo-ilc: error" in err, err
    for piece in expected:
        assert _fill(piece, scratch) in err, f"{piece!r} not in:\n{err}"
    assert work_started == [], f"refused only after it started: {work_started}"


def test_help_returns_zero(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--help"]) == 0
    assert "--mass-uncertainty" in capsys.readouterr().out


def test_one_rule_one_message(capsys: pytest.CaptureFixture[str]) -> None:
    """The same bad value gets the same message from every command that takes the flag."""
    messages = set()
    for command in ("simulate", "run", "compare", "tune", "analyze-loop"):
        assert main([command, "--mass-uncertainty", "-2"]) == 2
        err = capsys.readouterr().err
        messages.add(err.strip().splitlines()[-1].split(": error: ", 1)[1])
    assert len(messages) == 1, messages
    messages.clear()
    for command in ("simulate", "run", "compare", "paper"):
        assert main([command, "--trials", "0"]) == 2
        messages.add(capsys.readouterr().err.strip().splitlines()[-1].split(": error: ", 1)[1])
    assert messages == {"argument --trials: must be > 0, got '0' (the rule of parameter "
                        "max_trials)"}, messages


def test_flag_values_that_pass_still_run(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """The checks do not refuse what is fine: a valid --trials on a valid file, written
    outputs in new directories where the writer makes them."""
    short = tmp_path / "short.yaml"
    short.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 0.5\n')
    out = tmp_path / "run.json"
    # -0.9 (an arm a tenth of its model) is accepted and runs; its trials leave the error
    # envelope, which the run reports with exit 4 (issue 25), the JSON still written.
    assert main(["simulate", "--config", str(short), "--trials", "2", "--quiet",
                 "--mass-uncertainty", "-0.9", "--json", str(out)]) == 4
    assert out.is_file()
    plot = tmp_path / "f.png"
    assert main(["analyze-loop", "--cutoff", "5", "--mass-uncertainty", "0.1",
                 "--plot", str(plot)]) == 0
    assert plot.is_file()
    capsys.readouterr()


def test_a_file_is_validated_whole_whatever_the_flags(tmp_path: Path) -> None:
    """A wrong-typed key of --config is an error even when a flag overrides it."""
    from exo_ilc_ros.core.errors import ConfigError
    from exo_ilc_ros.core.params.config import load_config

    bad = tmp_path / "bad.yaml"
    bad.write_text('ilc_supervisor:\n  ros__parameters:\n    max_trials: "3"\n')
    with pytest.raises(ConfigError) as info:
        load_config(bad, {"max_trials": 5})
    assert info.value.key == "max_trials" and info.value.source == str(bad)


def test_a_bug_is_one_line_not_a_traceback(monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Whatever escapes the checks reaches the user as one line, not as a traceback."""
    import exo_ilc_ros.core.arm.urdf as urdf  # urdf's run path imports it when it runs

    def broken(*args: object) -> str:
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(urdf, "arm_urdf", broken)
    assert main(["urdf"]) == 1
    err = capsys.readouterr().err
    assert "internal error: ZeroDivisionError: float division by zero" in err
    assert "Traceback" not in err


def test_os_error_is_one_line(monkeypatch: pytest.MonkeyPatch,
                              capsys: pytest.CaptureFixture[str]) -> None:
    """A file that cannot be written after all (permissions, disk full): its name and why."""
    import exo_ilc_ros.core.arm.urdf as urdf  # urdf's run path imports it when it runs

    def refused(*args: object) -> str:
        raise PermissionError(13, "Permission denied", "arm.urdf")

    monkeypatch.setattr(urdf, "arm_urdf", refused)
    assert main(["urdf"]) == 2
    err = capsys.readouterr().err
    assert "exo-ilc urdf: error: arm.urdf: Permission denied" in err and "Traceback" not in err


def test_param_value_parsing() -> None:
    assert parse_value("[1, 2.5]") == [1.0, 2.5]
    assert parse_value("[1, 2]") == [1, 2]
    assert parse_value("sign") == "sign"
    with pytest.raises(ParamError, match=r"'\[1.0, 2.0' is not a valid YAML value"):
        parse_value("[1.0, 2.0")
    with pytest.raises(ParamError, match="64-bit"):
        parse_value(str(2**70))


def test_unknown_parameter_message_suggests_names() -> None:
    names = ["law", "max_trials", "schedule.position.threshold_low"]
    text = unknown_parameter("ilc_supervisor", "schedule.position.treshold_low", names)
    assert "'schedule.position.treshold_low'" in text
    assert "did you mean schedule.position.threshold_low?" in text
    assert "exo-ilc param list ilc_supervisor" in text
    text = unknown_parameter("ilc_supervisor", "zzz", names)
    assert "did you mean" not in text and "law, max_trials, schedule" in text


def test_environment_domain_id_is_checked(monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "lots")
    assert main(["param", "list", "ilc_supervisor"]) == 2
    err = capsys.readouterr().err
    assert "ROS_DOMAIN_ID" in err and "'lots'" in err and "Traceback" not in err


# --- ROS arguments: later overrides win; `exo-ilc param` against a running node -------------
def test_command_line_parameters_later_wins(tmp_path: Path) -> None:
    from exo_ilc_ros.nodes.parameters import command_line_parameters

    node_file = tmp_path / "node.yaml"
    node_file.write_text("ilc_supervisor:\n  ros__parameters:\n    max_trials: 7\n"
                         "    schedule:\n      position:\n        level_low: [1, 2, 3]\n")
    wild = tmp_path / "wild.yaml"
    wild.write_text('"/**":\n  ros__parameters:\n    max_trials: 9\n'
                    "/other_node:\n  ros__parameters:\n    max_trials: 11\n")
    fqn = "/ilc_supervisor"

    def value(*ros: str) -> object:
        given = command_line_parameters(["prog", "--ros-args", *ros], fqn)
        return given["max_trials"][0] if "max_trials" in given else None

    f, w = str(node_file), str(wild)
    assert value("--params-file", f, "-p", "max_trials:=3") == 3
    assert value("-p", "max_trials:=3", "--params-file", f) == 7
    assert value("--params-file", f, "--params-file", w) == 9  # a later /** beats a node key
    assert value("--params-file", w, "--params-file", f) == 7
    assert value("--params-file", f, "-p", "ilc_supervisor:max_trials:=4") == 4
    assert value("--params-file", f, "-p", "other:max_trials:=4") == 7
    assert value("-r", "__ns:=/x", "--params-file", w, "--", "-p", "max_trials:=1") == 9
    assert value() is None
    given = command_line_parameters(["prog", "--ros-args", "--params-file", f], fqn)
    assert given["schedule.position.level_low"] == ([1, 2, 3], f, False)
    given = command_line_parameters(["prog", "--ros-args", "--params-file", w], fqn)
    assert given["max_trials"] == (9, w, True)


def _start_supervisor(ros_args: list[str]) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "exo_ilc_ros.nodes.ilc_supervisor",
                             "--ros-args", *ros_args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True)


def _stop(process: subprocess.Popen[str]) -> str:
    process.send_signal(signal.SIGINT)
    try:
        out, _ = process.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    return out


def _param(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(["param", *argv, "--domain-id", os.environ["ROS_DOMAIN_ID"], "--timeout", "30"])
    out, err = capsys.readouterr()
    return code, out, err


def test_param_against_a_running_node(capsys: pytest.CaptureFixture[str]) -> None:
    """`-p` after `--params-file` wins at the node (and before it loses); `exo-ilc param` names
    an unknown parameter with suggestions, refuses bad values with the rule, no traceback."""
    node = _start_supervisor(["--params-file", str(SHIPPED), "-p", "max_trials:=3",
                              "-p", "max_trial:=4"])
    try:
        assert _param(capsys, "get", "ilc_supervisor", "max_trials")[:2] == (0, "3\n")
        code, _, err = _param(capsys, "set", "ilc_supervisor", "schedule.position.treshold_low",
                              "[1.0, 2.0, 1.0]")
        assert code == 2, err
        assert "has no parameter 'schedule.position.treshold_low'" in err
        assert "did you mean schedule.position.threshold_low" in err
        assert "undeclared" not in err
        code, _, err = _param(capsys, "get", "ilc_supervisor", "no_such")
        assert code == 2 and "has no parameter 'no_such'" in err, err
        code, _, err = _param(capsys, "set", "ilc_supervisor", "max_trials", "5")
        assert code == 2 and "max_trials = 5" in err and "cannot change while" in err, err
        code, _, err = _param(capsys, "set", "ilc_supervisor", "error_bound", "-1")
        assert code == 2 and "error_bound = -1" in err and "must be > 0" in err, err
        code, _, err = _param(capsys, "set", "ilc_supervisor", "law", "[1, 2]")
        assert code == 2 and "law" in err and "must be a string, got [1, 2]" in err, err
        code, out, err = _param(capsys, "set", "ilc_supervisor", "error_bound", "0.004")
        assert code == 0 and "successful" in out, err
    finally:
        log = _stop(node)
    assert "Traceback" not in log, log
    assert "-p max_trial:=4: max_trial: ilc_supervisor has no such parameter; ignored (did " \
        "you mean max_trials?)" in log, log
    node = _start_supervisor(["-p", "max_trials:=3", "--params-file", str(SHIPPED)])
    try:
        code, out, err = _param(capsys, "get", "ilc_supervisor", "max_trials")
        assert code == 0 and out.strip() != "3", (out, err)  # the later file wins
    finally:
        _stop(node)
    node = _start_supervisor(["-p", "max_trials:=abc"])
    try:
        code = node.wait(timeout=60)
    finally:
        log = _stop(node) if node.returncode is None else (node.stdout.read() if node.stdout
                                                           else "")
    assert code == 2 and "-p max_trials:=abc: max_trials: must be an integer" in log, log
    assert "Traceback" not in log, log


def test_rerun_note_says_what_happened_in_plain_words() -> None:
    """The note `analyze`/`paper`/`run` print for a trial that was run again."""
    from exo_ilc_ros.bag.reader import PROTOCOL_STEPS, rerun_note
    from exo_ilc_ros.core.protocol.timing import STEP_TIMEOUT
    from exo_ilc_ros.core.protocol.trial_protocol import Phase

    assert STEP_TIMEOUT == 30.0
    assert {p.value for p in Phase} - {"finished"} <= set(PROTOCOL_STEPS)
    note = rerun_note(108, {"trial": "108", "phase": "running"})
    assert note.startswith("trial 108 was aborted once and run again")
    assert "made no progress for 30 s" in note and "no new joint sample" in note
    assert "same feed-forward" in note and "results are unaffected" in note
    assert "nothing is learned from a discarded attempt" in note
    assert "{" not in note  # no raw dict
    assert rerun_note(108, {"trial": "108", "reason": "timeout", "phase": "running"}) == note
    note = rerun_note(4, {"trial": "4", "reason": "watchdog", "watchdog_trips": "2"})
    assert "(watchdog: the controller went without /joint_states" in note and "(2x)" in note
    assert "samples of the attempt never arrived" in rerun_note(5, {"reason": "lost",
                                                                    "lost": "3"})


@pytest.mark.parametrize(("ros_args", "expected"), [
    (["--params-file", "/nonexistent/params.yaml"], ["/nonexistent/params.yaml",
                                                     "Error opening YAML file"]),
    (["-p", "max_trials"], ["'-p max_trials'", "a rule is -p name:=value"]),
])
def test_node_refuses_bad_ros_arguments(ros_args: list[str], expected: list[str]) -> None:
    """A node started with a bad --ros-args value: rcl's reason in one line, exit code 2."""
    node = subprocess.run([sys.executable, "-m", "exo_ilc_ros.nodes.ilc_supervisor",
                           "--ros-args", *ros_args], capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL, check=False)
    out = node.stdout + node.stderr
    assert node.returncode == 2, out
    assert "Traceback" not in out and "error: invalid ROS arguments: " in out, out
    for piece in expected:
        assert piece in out, out
    assert "/project/src" not in out, out


def test_exponent_floats_read_as_rcl_reads_them(tmp_path: Path) -> None:
    """`1e-3` is a float for rcl (YAML 1.2); --config and the nodes read it the same way."""
    from exo_ilc_ros.core.params.config import load_config, load_ros_yaml
    from exo_ilc_ros.nodes.parameters import command_line_parameters

    assert load_ros_yaml("[1e-3, 2E1, -1.5e+2, 1_0]") == [0.001, 20.0, -150.0, 10]
    assert load_ros_yaml("v1e5") == "v1e5"
    path = tmp_path / "exp.yaml"
    path.write_text("plant_simulator:\n  ros__parameters:\n    integration_step: 1e-3\n")
    assert load_config(path)["integration_step"] == 0.001
    given = command_line_parameters(["n", "--ros-args", "--params-file", str(path), "-p",
                                     "real_time_rate:=2e0"], "/plant_simulator")
    assert given["integration_step"].value == 0.001 and given["real_time_rate"].value == 2.0


def test_a_database_that_fails_names_storage(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """A storage that passes the checks but fails when used (server down, no permission)."""
    from sqlalchemy.exc import OperationalError

    import exo_ilc_ros.analysis.tuning as tune  # tune's run path imports it when it runs

    def down(*args: object, **kwargs: object) -> None:
        raise OperationalError("connect", {}, ConnectionRefusedError("connection refused"))

    monkeypatch.setattr(tune, "optimize", down)
    url = f"sqlite:///{tmp_path}/t.db"
    assert main(["tune", "--storage", url, "--trials", "2", "--out",
                 str(tmp_path / "t.yaml")]) == 2
    err = capsys.readouterr().err
    assert f"argument --storage: cannot use the database {url!r}: connection refused" in err
    assert "Traceback" not in err and "internal error" not in err
