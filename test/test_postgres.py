"""`exo-ilc tune` on a PostgreSQL storage, the recipe of docs/tuning.md: two tuner processes share
one study on a real server that the test starts itself (Debian's ``postgresql`` package: initdb and
pg_ctl into a temporary directory, a free localhost port, trust authentication).

Skipped, with the reason, when the server binaries or the psycopg driver are missing; `.ci/run`
installs both, so CI runs it.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from glob import glob
from pathlib import Path

import optuna
import pytest

from exo_ilc_ros.cli.main import main

SHORT_YAML = '"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'


def _server_binaries() -> Path | None:
    """The directory holding initdb and pg_ctl: on PATH, else Debian's versioned directory."""
    found = shutil.which("initdb")
    if found and shutil.which("pg_ctl"):
        return Path(found).resolve().parent
    versions = sorted(glob("/usr/lib/postgresql/*/bin/pg_ctl"),
                      key=lambda p: int(Path(p).parts[-3]) if Path(p).parts[-3].isdigit() else 0)
    return Path(versions[-1]).parent if versions else None


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    """A throw-away PostgreSQL server on 127.0.0.1; yields its URL (database ``postgres``)."""
    pytest.importorskip("psycopg", reason="the psycopg driver is not installed "
                        "(pip install 'psycopg[binary]', part of the test extras)")
    bindir = _server_binaries()
    if bindir is None:
        pytest.skip("PostgreSQL server binaries (initdb, pg_ctl) not found: install Debian's "
                    "postgresql package (apt-get install -y postgresql; .ci/run does)")
    as_user: list[str] = []
    if os.geteuid() == 0:  # initdb refuses root: run the server as the postgres user
        if shutil.which("runuser") is None:
            pytest.skip("running as root without runuser to start PostgreSQL as its own user")
        try:
            import pwd

            owner = pwd.getpwnam("postgres")
        except KeyError:
            pytest.skip("running as root and there is no 'postgres' user to run the server as")
        as_user = ["runuser", "-u", "postgres", "--"]
    # As root, under /tmp: the postgres user must reach it (TMPDIR may sit under /root).
    root = Path(tempfile.mkdtemp(prefix="exo_ilc_pg_", dir="/tmp" if as_user else None))
    if as_user:
        os.chown(root, owner.pw_uid, owner.pw_gid)
    data, log = root / "data", root / "server.log"
    port = _free_port()

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([*as_user, *args], capture_output=True, text=True, timeout=120,
                              stdin=subprocess.DEVNULL, check=False, cwd=root)

    try:
        init = run(str(bindir / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres",
                   "--no-sync", "--no-instructions")
        assert init.returncode == 0, init.stdout + init.stderr
        start = run(str(bindir / "pg_ctl"), "-D", str(data), "-l", str(log), "-w", "-t", "60",
                    "-o", f"-p {port} -k {root} -c listen_addresses=127.0.0.1 -c fsync=off",
                    "start")
        assert start.returncode == 0, start.stdout + start.stderr + \
            (log.read_text() if log.exists() else "")
        yield f"postgresql://postgres@127.0.0.1:{port}/postgres"
    finally:
        run(str(bindir / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop")
        shutil.rmtree(root, ignore_errors=True)


def test_two_tuner_processes_share_one_study_on_postgres(tmp_path: Path,
                                                         postgres_url: str) -> None:
    """The recipe of docs/tuning.md: the same command on two "machines" (processes) with one
    --study-name and --storage postgresql://...; then --budget 0 writes the best of both."""
    short = tmp_path / "short.yaml"
    short.write_text(SHORT_YAML)
    common = ["tune", "--config", str(short), "--mass-uncertainty", "0.1", "--trials", "4",
              "--jobs", "1", "--study-name", "shared", "--storage", postgres_url]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    workers = [subprocess.Popen([sys.executable, "-m", "exo_ilc_ros.cli.main", *common,
                                 "--budget", "3", "--out", str(tmp_path / f"w{i}.yaml")],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                stdin=subprocess.DEVNULL, env=env, cwd=tmp_path)
               for i in (1, 2)]
    for worker in workers:
        out, _ = worker.communicate(timeout=240)
        assert worker.returncode == 0, out[-3000:]
        assert "wrote" in out and "Traceback" not in out
    study = optuna.load_study(study_name="shared", storage=postgres_url)
    done = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(done) == 6, [t.state for t in study.trials]  # 3 from each process, one study
    best = tmp_path / "best.yaml"
    assert main([*common, "--budget", "0", "--out", str(best)]) == 0
    assert f"Objective {study.best_value:.1f}" in best.read_text()


def test_missing_database_driver_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Without psycopg, `--storage postgresql://...` says what to install, no traceback (and
    before any server is contacted)."""
    monkeypatch.setitem(sys.modules, "psycopg", None)  # import psycopg -> ModuleNotFoundError
    short = tmp_path / "short.yaml"
    short.write_text(SHORT_YAML)
    code = main(["tune", "--config", str(short), "--mass-uncertainty", "0.1", "--trials", "2",
                 "--budget", "1", "--jobs", "1", "--storage", "postgresql://u@db-host/optuna",
                 "--out", str(tmp_path / "t.yaml")])
    err = capsys.readouterr().err
    assert code == 2
    assert "the database driver 'psycopg'" in err and "pip install 'psycopg[binary]'" in err
    assert "Traceback" not in err and not (tmp_path / "t.yaml").exists()


def test_a_lost_race_to_create_the_tables_is_retried(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two tuners starting together on an empty database: the one whose CREATE TABLE loses
    (PostgreSQL: duplicate key in pg_type) tries again and finds the tables; a connection
    failure is not retried and is one line."""
    from sqlalchemy.exc import IntegrityError, OperationalError

    from exo_ilc_ros.analysis import tuning

    calls: list[int] = []
    real = optuna.create_study

    def flaky(**kwargs: object) -> optuna.Study:
        calls.append(1)
        if len(calls) == 1:
            raise IntegrityError("CREATE TABLE studies", {}, Exception(
                'duplicate key value violates unique constraint "pg_type_typname_nsp_index"'))
        return real(**kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(tuning.optuna, "create_study", flaky)
    study = tuning._create_study("sqlite:///:memory:", "s", None)
    assert study.study_name == "s" and len(calls) == 2

    def down(**kwargs: object) -> optuna.Study:
        calls.append(1)
        raise OperationalError("connect", {}, Exception("connection refused\nmore"))

    monkeypatch.setattr(tuning.optuna, "create_study", down)
    calls.clear()
    with pytest.raises(tuning.TuningError, match=r"cannot open the database \(connection "
                       r"refused\)$"):
        tuning._create_study("sqlite:///:memory:", "s", None)
    assert len(calls) == 1
