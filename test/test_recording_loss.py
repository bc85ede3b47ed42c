"""Nothing recorded is lost: over a graph run with the machine loaded (a CPU hog beside it),
every message each node published (its own count, printed when it stops) is in the bag, per
node and topic. Once, the recorder missed 26 of 153 /clock messages in trial 1: the plant
offered /clock reliable with a history of depth 1, so a sample the loaded recorder had not yet
acknowledged was replaced before it could be repaired (now depth 1000, ``CLOCK_QOS``).

The issue's "no loss in 20 runs of 10 trials under load" is the slow test here, run once:
20 runs of 10 trials of 501 samples, about 10 630 messages each, none lost (9 min). The
normal suite runs one short run; ``make soak`` runs the 20 (a nightly target, not in
``make test``).

Once, before the counts were printed where they are now, the soak found one supervisor
/diagnostics message more in the bag than the supervisor had counted. It is not a duplicate:
DDS delivers a reliable writer's sample once per reader (by its sequence number), and the
recorder writes each message it takes exactly once (``BagRecorder.poll`` moves every taken
message either into a write or into ``unwritten``, written with the next batch). It was a
message published after the count was printed: a stopping process printed its nodes' counts
as soon as they left the executor, but the callbacks already queued for them (a controller
status that arrived while the process was stopping) still ran and could make the supervisor
publish (its ``finished`` event sends its health at once). ``run_nodes`` now prints the counts
only after those callbacks ran (``_settle``; ``test_inbox.py::
test_run_nodes_prints_the_counts_once_nothing_more_is_published`` holds the printed count
against what such callbacks published), and nothing of a node runs after its count is
printed but its destruction, which publishes nothing. The soak run after that change found
every message of 20 runs."""

from __future__ import annotations

import glob
import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.nodes.common import PUBLISHED_PREFIX
from exo_ilc_ros.orchestration.graph import GraphSession
from exo_ilc_ros.orchestration.recording import Recording
from exo_ilc_ros.wire import topics
from exo_ilc_ros.wire.publishers import CONTROLLER, PLANT, RECORDER, SUPERVISOR

pytestmark = pytest.mark.graph

PUBLISHER = {topics.JOINT_STATES: PLANT, topics.CLOCK: PLANT,
             topics.EFFORT_COMMANDS: CONTROLLER, topics.FEEDFORWARD: SUPERVISOR,
             topics.TRIAL_EVENTS: SUPERVISOR, topics.TRIAL_SUMMARY: SUPERVISOR,
             topics.TRIAL_METRICS: SUPERVISOR}
"""The node that publishes each recorded topic (/diagnostics: the node its status names)."""
HOG = "import itertools\nfor _ in itertools.count(): pass\n"


def published(log_dir: Path) -> Counter[tuple[str, str]]:
    """(node, topic) -> what the node says it published (its log's last words)."""
    counts: Counter[tuple[str, str]] = Counter()
    for log in log_dir.glob("*.log"):
        for line in log.read_text(errors="replace").splitlines():
            if line.startswith(PUBLISHED_PREFIX):
                node, _, text = line[len(PUBLISHED_PREFIX):].partition(" ")
                for topic, count in json.loads(text).items():
                    counts[(node, topic)] += count
    return counts


def recorded(bag: Path) -> Counter[tuple[str, str]]:
    """(node, topic) -> messages in the bag (/diagnostics by the node its status names)."""
    counts: Counter[tuple[str, str]] = Counter()
    for file in sorted(glob.glob(str(bag / "*.mcap"))):
        with open(file, "rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages():
                if channel.topic == topics.DIAGNOSTICS:
                    for node in {status.name.split("/")[0] for status in msg.status}:
                        counts[(node, channel.topic)] += 1
                elif channel.topic in PUBLISHER:
                    counts[(PUBLISHER[channel.topic], channel.topic)] += 1
    return counts


def loaded_run(directory: Path, trials: int, duration: float | None = 1.0) -> tuple[
        Counter[tuple[str, str]], Counter[tuple[str, str]]]:
    """One recorded graph run of ``trials`` trials with a CPU hog beside it; (published,
    recorded) per (node, topic), the recorder's own status left out (it reports until its
    last moment, after its last drain). ``duration``: of the trajectory (None: the shipped
    one)."""
    overrides: dict[str, object] = {"max_trials": trials, "wait_for_recorder": True}
    if duration is not None:
        overrides["trajectory.duration"] = duration
    config = load_config(overrides=overrides)
    log_dir = directory / "logs"
    hog = subprocess.Popen([sys.executable, "-c", HOG], stdin=subprocess.DEVNULL)
    try:
        with Recording(config, directory / "bags") as recording, \
                GraphSession(config, nodes=recording.graph_nodes(), log_dir=log_dir) as session:
            session.spin_until(lambda: session.finished, timeout=600, stall_timeout=180)
            bag = recording.path
    finally:
        hog.kill()
        hog.wait()
    sent, kept = published(log_dir), recorded(bag)
    for counts in (sent, kept):
        counts.pop((RECORDER, topics.DIAGNOSTICS), None)
    return sent, kept


def _assert_nothing_lost(sent: Counter[tuple[str, str]],
                         kept: Counter[tuple[str, str]], trials: int) -> None:
    assert sent[(SUPERVISOR, topics.TRIAL_METRICS)] >= trials  # the counts were really read
    assert sent[(PLANT, topics.CLOCK)] > 0 and sent[(CONTROLLER, topics.DIAGNOSTICS)] > 0
    lost = {key: sent[key] - kept[key] for key in sent | kept if sent[key] != kept[key]}
    assert not lost, f"published - recorded per (node, topic): {lost}"


def test_the_bag_holds_every_message_published_under_load(tmp_path: Path) -> None:
    sent, kept = loaded_run(tmp_path, trials=2)
    _assert_nothing_lost(sent, kept, 2)


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("EXO_ILC_SOAK"), reason="the 20-run soak (~9 min): "
                    "make soak (EXO_ILC_SOAK=1) runs it; the normal suite runs the 2-trial case "
                    "above")
def test_no_loss_in_20_runs_of_10_trials_under_load(tmp_path: Path) -> None:
    """The issue's figure, with the shipped 15 s trials (EXO_ILC_LOSS_RUNS overrides the 20
    runs)."""
    runs = int(os.environ.get("EXO_ILC_LOSS_RUNS", "20"))
    total: Counter[tuple[str, str]] = Counter()
    for run in range(runs):
        sent, kept = loaded_run(tmp_path / f"run{run}", trials=10, duration=None)
        _assert_nothing_lost(sent, kept, 10)
        total.update(sent)
        print(f"run {run + 1}/{runs}: {sum(sent.values())} messages published, all recorded",
              flush=True)
    for (node, topic), count in sorted(total.items()):  # the per-topic figure, for the docs
        print(f"  {node} {topic}: {count} published, {count} in the bags")
