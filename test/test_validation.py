"""Property tests (hypothesis) of the message validators and of live parameter updates.

Deterministic in CI: every test is ``derandomize=True`` with no example database. Cases per run
(max_examples): joint states 500 good + 600 bad, effort commands 250 + 400, feed-forward
profiles 100 + 150, parameter updates 250 good (and 4 for each live parameter alone) + 400 bad:
~2800 in total, every mutation class drawn in each bad-case test (10 500 before: 3.5 min of
the suite on a loaded 2-core machine).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.loop.wire_input import (
    Cause,
    FeedforwardProfile,
    JointSample,
    LogOnce,
    Rejection,
    validate_effort_command,
    validate_feedforward,
    validate_joint_state,
)
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.params.validation import validate_update

JOINTS = ["shoulder_flexion", "shoulder_abduction", "elbow_flexion"]
LIMIT = [40.0, 40.0, 20.0]


def ci(n: int) -> settings:
    """Deterministic settings with ``n`` examples."""
    return settings(max_examples=n, derandomize=True, database=None, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])


@st.composite
def joint_states(draw: st.DrawFn) -> dict[str, Any]:
    """A good JointState in any joint order (effort present or empty)."""
    names = draw(st.permutations(JOINTS))
    n = len(names)
    with_effort = draw(st.booleans())
    return {"names": list(names), "stamp_ns": draw(st.integers(1, 10**15)),
            "position": draw(st.lists(finite, min_size=n, max_size=n)),
            "velocity": draw(st.lists(finite, min_size=n, max_size=n)),
            "effort": draw(st.lists(finite, min_size=n, max_size=n)) if with_effort else []}


def _call(msg: dict[str, Any], last: int | None = None) -> JointSample | Rejection:
    return validate_joint_state(msg["names"], msg["stamp_ns"], msg["position"],
                                msg["velocity"], msg["effort"], JOINTS, last)


@ci(500)
@given(joint_states(), st.integers(0, 10**6))
def test_good_joint_state_accepted_and_reordered(msg: dict[str, Any], gap: int) -> None:
    out = _call(msg, msg["stamp_ns"] - 1 - gap)
    assert isinstance(out, JointSample), out
    order = [msg["names"].index(j) for j in JOINTS]
    assert out.stamp_ns == msg["stamp_ns"]
    assert np.array_equal(out.position, np.array(msg["position"])[order])
    assert np.array_equal(out.velocity, np.array(msg["velocity"])[order])
    if msg["effort"]:
        assert out.effort is not None
        assert np.array_equal(out.effort, np.array(msg["effort"])[order])
    else:
        assert out.effort is None


MUTATIONS = ("nan", "length", "unknown", "duplicate", "missing", "stamp_back", "stamp_negative",
             "not_numeric")
EXPECTED = {"nan": {Cause.NON_FINITE}, "length": {Cause.WRONG_LENGTH},
            "unknown": {Cause.UNKNOWN_JOINT}, "duplicate": {Cause.DUPLICATE_JOINT},
            "missing": {Cause.MISSING_JOINT},
            "stamp_back": {Cause.NON_MONOTONIC_STAMP}, "stamp_negative": {Cause.BAD_STAMP},
            "not_numeric": {Cause.NOT_NUMERIC}}


@ci(600)
@given(joint_states(), st.sampled_from(MUTATIONS), st.data())
def test_bad_joint_state_rejected(msg: dict[str, Any], mutation: str, data: st.DataObject) -> None:
    last = None
    field = data.draw(st.sampled_from(["position", "velocity", "effort"]))
    if field == "effort" and not msg["effort"]:
        msg["effort"] = [0.0] * len(msg["names"])
    if mutation == "nan":
        i = data.draw(st.integers(0, len(msg[field]) - 1))
        msg[field][i] = data.draw(non_finite)
    elif mutation == "length":
        extra = data.draw(st.integers(1, 3))
        if data.draw(st.booleans()) and len(msg[field]) > 1:
            msg[field] = msg[field][:-1]
        else:
            msg[field] = msg[field] + [0.0] * extra
    elif mutation == "unknown":
        i = data.draw(st.integers(0, len(msg["names"]) - 1))
        msg["names"][i] = data.draw(st.text(min_size=0, max_size=8).filter(
            lambda s: s not in JOINTS))
    elif mutation == "duplicate":
        i, k = data.draw(st.lists(st.integers(0, 2), min_size=2, max_size=2, unique=True))
        msg["names"][i] = msg["names"][k]
    elif mutation == "missing":
        i = data.draw(st.integers(0, 2))
        for f in ("names", "position", "velocity", "effort"):
            if msg[f]:
                del msg[f][i]
    elif mutation == "stamp_back":
        last = msg["stamp_ns"] + data.draw(st.integers(0, 10**9))
    elif mutation == "stamp_negative":
        msg["stamp_ns"] = data.draw(st.integers(-(10**12), -1))
    elif mutation == "not_numeric":
        i = data.draw(st.integers(0, len(msg[field]) - 1))
        msg[field][i] = data.draw(st.sampled_from(["1.0", None, True, 1j, [1.0]]))
    out = _call(msg, last)
    assert isinstance(out, Rejection), (mutation, msg)
    assert out.cause in EXPECTED[mutation], (mutation, out)
    assert out.message


@ci(250)
@given(st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3))
def test_good_effort_accepted_unchanged(fractions: list[float]) -> None:
    values = [f * lim * s for f, lim, s in zip(fractions, LIMIT, (1, -1, 1), strict=True)]
    out = validate_effort_command(values, LIMIT)
    assert isinstance(out, np.ndarray)
    assert out.tolist() == values


@ci(400)
@given(st.lists(finite, min_size=3, max_size=3), st.sampled_from(["nan", "length", "limit",
                                                                   "type"]), st.data())
def test_bad_effort_rejected(values: list[float], mutation: str, data: st.DataObject) -> None:
    values = [float(np.clip(v, -lim, lim)) for v, lim in zip(values, LIMIT, strict=True)]
    i = data.draw(st.integers(0, 2))
    bad: Any = list(values)
    if mutation == "nan":
        bad[i] = data.draw(non_finite)
    elif mutation == "length":
        bad = data.draw(st.sampled_from([bad[:i], [*bad, 0.0], [], [*bad, *bad]]))
    elif mutation == "limit":
        bad[i] = math.copysign(LIMIT[i] * (1 + data.draw(st.floats(1e-9, 1e6))),
                               data.draw(st.sampled_from([1.0, -1.0])))
    else:
        bad[i] = data.draw(st.sampled_from(["0", None, False]))
    out = validate_effort_command(bad, LIMIT)
    assert isinstance(out, Rejection), (mutation, bad)
    expect = {"nan": Cause.NON_FINITE, "length": Cause.WRONG_LENGTH, "limit": Cause.OUT_OF_LIMIT,
              "type": Cause.NOT_NUMERIC}[mutation]
    assert out.cause is expect


SAMPLES, PERIOD_NS = 6, 10_000_000


@st.composite
def profiles(draw: st.DrawFn) -> dict[str, Any]:
    """A good feed-forward profile (JointTrajectory points) in any joint order."""
    names = list(draw(st.permutations(JOINTS)))
    rows = st.lists(st.lists(finite, min_size=3, max_size=3), min_size=SAMPLES,
                    max_size=SAMPLES)
    return {"names": names, "times": [i * PERIOD_NS for i in range(SAMPLES)],
            "pos": draw(rows), "vel": draw(rows), "acc": draw(rows)}


def _profile(p: dict[str, Any], limit: list[float] | None = None
             ) -> FeedforwardProfile | Rejection:
    return validate_feedforward(p["names"], p["times"], p["pos"], p["vel"], p["acc"], JOINTS,
                                SAMPLES, PERIOD_NS, limit)


@ci(100)
@given(profiles())
def test_good_feedforward_accepted_and_reordered(p: dict[str, Any]) -> None:
    out = _profile(p, [0.0, 0.0, 0.0])
    assert isinstance(out, FeedforwardProfile), out
    order = [p["names"].index(j) for j in JOINTS]
    assert np.array_equal(out.feedforward, np.array(p["acc"])[:, order])
    assert np.array_equal(out.position, np.array(p["pos"])[:, order])


@ci(150)
@given(profiles(), st.sampled_from(["nan", "points", "row", "times", "limit", "names"]),
       st.data())
def test_bad_feedforward_rejected(p: dict[str, Any], mutation: str, data: st.DataObject) -> None:
    limit = None
    i = data.draw(st.integers(0, SAMPLES - 1))
    j = data.draw(st.integers(0, 2))
    key = data.draw(st.sampled_from(["pos", "vel", "acc"]))
    if mutation == "nan":
        p[key][i][j] = data.draw(non_finite)
    elif mutation == "points":
        p[key] = p[key][:-1]
    elif mutation == "row":
        p[key][i] = p[key][i][:j]
    elif mutation == "times":
        p["times"][i] += data.draw(st.sampled_from([-1, 1, PERIOD_NS]))
    elif mutation == "limit":
        limit = [1.0, 1.0, 1.0]
        p["acc"][i][j] = data.draw(st.sampled_from([1.5, -2.0, 1e6]))
    else:
        p["names"][j] = "wrist"
    out = _profile(p, limit)
    assert isinstance(out, Rejection), (mutation, p)


def test_log_once_counts_per_cause() -> None:
    log = LogOnce()
    nan = Rejection(Cause.NON_FINITE, "a")
    assert log.record(nan)
    assert not log.record(Rejection(Cause.NON_FINITE, "b"))
    assert log.record(Rejection(Cause.WRONG_LENGTH, "c"))
    assert log.counts == {Cause.NON_FINITE: 2, Cause.WRONG_LENGTH: 1}
    assert log.last[Cause.NON_FINITE] == "b"
    assert log.total == 3
    assert ("rejected/non_finite", "2") in log.as_values()


# --- parameter updates --------------------------------------------------------------------

BASE = load_config()
LIVE = [p for p in schema.PARAMETERS if p.live]
THRESHOLDS = {f"schedule.{t}.threshold_{s}" for t in ("position", "velocity", "acceleration")
              for s in ("low", "high")}
NYQUIST = 0.5 / BASE["control.period"]


def good_value(p: schema.Parameter) -> st.SearchStrategy[Any]:
    """Values ``p``'s rule accepts (thresholds handled in pairs elsewhere)."""
    low = 1e-6 if p.strictly_positive else (p.minimum if p.minimum is not None else -1e3)
    if p.name == "q_filter.cutoff_hz":
        return st.floats(1e-3, NYQUIST * 0.999)
    if p.name == "norm_optimal.effort_margin":
        return st.floats(0.0, 0.999)
    if p.name in ("assist_as_needed.forgetting", "abort.backoff"):
        return st.floats(1e-3, 1.0)
    if p.kind is schema.Kind.DOUBLE:
        return st.floats(low, 1e3)
    if p.kind is schema.Kind.INTEGER:
        return st.integers(max(int(math.ceil(low)), 0 if not p.strictly_positive else 1), 8)
    if p.kind is schema.Kind.BOOL:
        return st.booleans()
    if p.kind is schema.Kind.STRING:
        return st.sampled_from(p.choices)
    assert p.kind is schema.Kind.DOUBLE_ARRAY and p.per_joint
    return st.lists(st.floats(low, 1e3), min_size=3, max_size=3)


@st.composite
def good_changes(draw: st.DrawFn) -> dict[str, Any]:
    """1-4 live parameters changed to valid values (thresholds as increasing pairs)."""
    plain = [p for p in LIVE if p.name not in THRESHOLDS]
    chosen = draw(st.lists(st.sampled_from(plain), min_size=0, max_size=3, unique=True))
    changes = {p.name: draw(good_value(p)) for p in chosen}
    for term in draw(st.lists(st.sampled_from(["position", "velocity", "acceleration"]),
                              max_size=2, unique=True)):
        low = draw(st.lists(st.floats(0.0, 100.0), min_size=3, max_size=3))
        gap = draw(st.lists(st.floats(1e-3, 100.0), min_size=3, max_size=3))
        changes[f"schedule.{term}.threshold_low"] = low
        changes[f"schedule.{term}.threshold_high"] = [a + b for a, b in zip(low, gap,
                                                                            strict=True)]
    return changes


@ci(250)
@given(good_changes())
def test_good_update_accepted_unchanged(changes: dict[str, Any]) -> None:
    out = validate_update(BASE, changes)
    assert isinstance(out, Config), out
    for name in schema.BY_NAME:
        expected = changes.get(name, BASE[name])
        assert out[name] == expected, name


@pytest.mark.parametrize("name", [p.name for p in LIVE if p.name not in THRESHOLDS])
@ci(4)
@given(st.data())
def test_each_live_parameter_alone_accepted_unchanged(name: str, data: st.DataObject) -> None:
    """Every live parameter (the thresholds: in pairs above) changed alone to values its rule
    accepts: the random sets above need ~1000 cases to reach all of them."""
    value = data.draw(good_value(schema.BY_NAME[name]))
    out = validate_update(BASE, {name: value})
    assert isinstance(out, Config), out
    assert out[name] == value
    assert all(out[other] == BASE[other] for other in schema.BY_NAME if other != name)


BAD = ("nan", "length", "negative", "type", "threshold_order", "not_live", "unknown")


@ci(400)
@given(st.sampled_from(BAD), st.data())
def test_bad_update_rejected(mutation: str, data: st.DataObject) -> None:
    arrays = [p for p in LIVE if p.kind is schema.Kind.DOUBLE_ARRAY]
    p = data.draw(st.sampled_from(arrays))
    value = list(BASE[p.name])
    i = data.draw(st.integers(0, 2))
    changes: dict[str, Any]
    if mutation == "nan":
        numeric = [q for q in LIVE if q.kind in (schema.Kind.DOUBLE, schema.Kind.DOUBLE_ARRAY)]
        p = data.draw(st.sampled_from(numeric))
        bad = data.draw(non_finite)
        if p.kind is schema.Kind.DOUBLE:
            changes = {p.name: bad}
        else:
            value = list(BASE[p.name])
            value[i] = bad
            changes = {p.name: value}
    elif mutation == "length":
        n = data.draw(st.sampled_from([0, 1, 2, 4, 7]))
        changes = {p.name: (value * 3)[:n]}
    elif mutation == "negative":
        value[i] = -data.draw(st.floats(1e-12, 1e6))
        changes = {p.name: value}
    elif mutation == "type":
        target = data.draw(st.sampled_from(LIVE))
        wrong = {schema.Kind.DOUBLE: "0.1", schema.Kind.INTEGER: 1.5,
                 schema.Kind.BOOL: "yes", schema.Kind.STRING: 3,
                 schema.Kind.DOUBLE_ARRAY: ["a", "b", "c"],
                 schema.Kind.STRING_ARRAY: [1, 2, 3]}[target.kind]
        p = target
        changes = {p.name: data.draw(st.sampled_from([wrong, None]))}
    elif mutation == "threshold_order":
        term = data.draw(st.sampled_from(["position", "velocity", "acceleration"]))
        high = list(BASE[f"schedule.{term}.threshold_high"])
        low = list(BASE[f"schedule.{term}.threshold_low"])
        low[i] = high[i] + data.draw(st.floats(0.0, 100.0))
        changes = {f"schedule.{term}.threshold_low": low}
    elif mutation == "not_live":
        fixed = [q for q in schema.PARAMETERS if not q.live]
        p = data.draw(st.sampled_from(fixed))
        changes = {p.name: BASE[p.name]}
    else:
        changes = {data.draw(st.text(min_size=1, max_size=12).filter(
            lambda s: s not in schema.BY_NAME and s not in schema.ROS_BUILTIN)): 1.0}
    extra = data.draw(good_changes())
    merged = {**extra, **changes}
    if mutation == "threshold_order":  # a good pair drawn for the same term would hide it
        merged = {k: v for k, v in merged.items() if k not in THRESHOLDS or k in changes}
    out = validate_update(BASE, merged)
    assert isinstance(out, ConfigError), (mutation, merged)
    assert out.key in merged or mutation == "threshold_order", (out.key, merged)
    assert out.rule


def test_update_rejections_name_the_rule() -> None:
    out = validate_update(BASE, {"schedule.position.level_low": [-1.0, 0.0, 0.0]})
    assert isinstance(out, ConfigError)
    assert out.key == "schedule.position.level_low" and ">= 0" in out.rule
    out = validate_update(BASE, {"mass_uncertainty": 0.1})
    assert isinstance(out, ConfigError) and "restart" in out.rule
    restarted = validate_update(BASE, {"mass_uncertainty": 0.1}, live_only=False)
    assert isinstance(restarted, Config) and restarted["mass_uncertainty"] == 0.1
    assert validate_update(BASE, {"use_sim_time": True}) is BASE
    out = validate_update(BASE, {"error_bound": 0.006}, node="plant_simulator")
    assert isinstance(out, ConfigError) and out.key == "error_bound" and out.rule == \
        "unknown parameter"  # the supervisor's, not the plant's
    assert validate_update(BASE, {"error_bound": 0.006}, node="ilc_supervisor")["error_bound"] \
        == 0.006


@pytest.mark.parametrize("envelope", [[0.0, 1.0, 1.0], [-0.1, 1.0, 1.0], [1.0, 1.0],
                                      [math.nan, 1.0, 1.0]])
def test_error_envelope_rules(envelope: list[float]) -> None:
    out = validate_update(BASE, {"safety.error_envelope": envelope})
    assert isinstance(out, ConfigError) and out.key == "safety.error_envelope"
