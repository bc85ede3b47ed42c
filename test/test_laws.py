"""The learning laws against hand-computed cases (every number below was worked out by hand)."""

from __future__ import annotations

import numpy as np
import pytest

from exo_ilc_ros.core import (
    ErrorSum,
    InitialFeedforward,
    LinearLaw,
    Memory,
    SampledReference,
    ScheduleIndex,
    SignLaw,
    StepSchedule,
    TrialRecord,
    error_sums,
    iterations_to_bound,
    sgn,
)

# Two joints, four samples, period 0.5 s.
E = np.array([[0.1, 0.0], [0.2, -0.3], [-0.1, 0.0], [0.0, 0.9]])  # e = q_d - q
V = np.array([[0.0, 0.0], [1.0, -1.0], [2.0, 0.0], [1.0, 2.0]])  # measured velocity (q_d' = 0)
# np.gradient(V, 0.5): joint 1 [2, 2, 0, -2], joint 2 [-2, 0, 3, 4]; q_d'' = [1, 0]
EDD = np.array([[-1.0, 2.0], [-1.0, 0.0], [1.0, -3.0], [3.0, -4.0]])
FEEDFORWARD = np.array([[0.5, -0.5]] * 4)
CONTROL = np.array([[2.0, 3.0], [4.0, 5.0], [6.0, 7.0], [8.0, 9.0]])


@pytest.fixture
def record() -> TrialRecord:
    reference = SampledReference(np.arange(4) * 0.5, np.zeros((4, 2)), np.zeros((4, 2)),
                                 np.array([[1.0, 0.0]] * 4), 0.5)
    return TrialRecord(1, reference, -E, V, FEEDFORWARD, CONTROL, np.zeros((4, 2)))


def schedules() -> tuple[StepSchedule, StepSchedule, StepSchedule]:
    position = StepSchedule.from_values([0.1, 0.5], [0.3, 1.0], [0.01, 0.02], [0.1, 0.2],
                                        [1.0, 2.0])
    velocity = StepSchedule.from_values([1.0, 2.0], [3.0, 4.0], [0.001, 0.002], [0.01, 0.02],
                                        [0.1, 0.2])
    acceleration = StepSchedule.from_values([1.0, 4.0], [5.0, 8.0], [0.003, 0.004],
                                            [0.03, 0.04], [0.3, 0.4])
    return position, velocity, acceleration


def test_record_errors(record: TrialRecord) -> None:
    np.testing.assert_allclose(record.error, E)
    np.testing.assert_allclose(record.error_velocity, -V)
    np.testing.assert_allclose(record.error_acceleration, EDD)
    np.testing.assert_allclose(record.max_abs_error, [0.2, 0.9])


def test_error_sums_eq13(record: TrialRecord) -> None:
    np.testing.assert_allclose(error_sums(record, ErrorSum.ABS_OF_SUM),
                               [[0.2, 0.6], [4.0, 1.0], [2.0, 5.0]])
    np.testing.assert_allclose(error_sums(record, ErrorSum.SUM_OF_ABS),
                               [[0.4, 1.2], [4.0, 3.0], [6.0, 9.0]])


def test_sign_function_eq12() -> None:
    np.testing.assert_array_equal(sgn(np.array([-2.0, -1e-300, 0.0, -0.0, 1e-300, 3.0])),
                                  [-1.0, -1.0, 0.0, 0.0, 1.0, 1.0])


def test_step_schedule_boundaries() -> None:
    """Eq (22), joint 1: 0.9 if s > 20; 0.03 if 1.5 < s <= 20; 0.001 if s <= 1.5."""
    m = StepSchedule.from_values([1.5], [20.0], [0.001], [0.03], [0.9])
    cases = {0.0: 0.001, 1.5: 0.001, np.nextafter(1.5, 2.0): 0.03, 10.0: 0.03, 20.0: 0.03,
             np.nextafter(20.0, 21.0): 0.9, 1e6: 0.9}
    for s, expected in cases.items():
        assert m.level(np.array([s]))[0] == expected, s
    np.testing.assert_array_equal(m.band(np.array([1.0, 2.0, 30.0]).reshape(3, 1)).ravel(),
                                  [0, 1, 2])


def test_step_schedule_rejects_bad_values() -> None:
    with pytest.raises(ValueError, match="increase"):
        StepSchedule.from_values([2.0], [1.0], [0.0], [0.0], [0.0])
    with pytest.raises(ValueError, match="non-negative"):
        StepSchedule.from_values([1.0], [2.0], [-0.1], [0.0], [0.0])


def test_sign_law_total_input_own_sums_abs_of_sum(record: TrialRecord) -> None:
    law = SignLaw(*schedules())  # the canonical reading
    update = law.update(record)
    np.testing.assert_allclose(update.levels, [[0.1, 0.2], [0.1, 0.002], [0.03, 0.04]])
    np.testing.assert_allclose(update.feedforward, [[2.07, 3.04], [3.97, 4.802],
                                                    [5.83, 6.96], [7.93, 9.158]], atol=1e-12)


def test_sign_law_feedforward_memory_position_sums(record: TrialRecord) -> None:
    law = SignLaw(*schedules(), memory=Memory.FEEDFORWARD,
                  schedule_index=ScheduleIndex.POSITION_SUM)
    update = law.update(record)
    np.testing.assert_allclose(update.levels, [[0.1, 0.2], [0.001, 0.002], [0.003, 0.004]])
    np.testing.assert_allclose(update.feedforward, [[0.597, -0.496], [0.596, -0.698],
                                                    [0.402, -0.504], [0.502, -0.306]],
                               atol=1e-12)


def test_sign_law_sum_of_abs(record: TrialRecord) -> None:
    law = SignLaw(*schedules(), error_sum=ErrorSum.SUM_OF_ABS)
    update = law.update(record)
    np.testing.assert_allclose(update.levels, [[1.0, 2.0], [0.1, 0.02], [0.3, 0.4]])
    np.testing.assert_allclose(update.feedforward, [[2.7, 3.4], [4.6, 3.02], [5.2, 6.6],
                                                    [8.2, 10.58]], atol=1e-12)


def test_initial_feedforward_options(record: TrialRecord) -> None:
    ref = record.reference
    assert not SignLaw(*schedules()).initial_feedforward(ref).any()
    law = SignLaw(*schedules(), initial=InitialFeedforward.REFERENCE_ACCELERATION)
    np.testing.assert_array_equal(law.initial_feedforward(ref), ref.acceleration)


def test_linear_law(record: TrialRecord) -> None:
    law = LinearLaw(np.array([1.0, 2.0]), np.array([0.1, 0.0]), np.array([0.0, 0.5]))
    update = law.update(record)
    assert update.levels is None
    np.testing.assert_allclose(update.feedforward, [[2.1, 4.0], [4.1, 4.4], [5.7, 5.5],
                                                    [7.9, 8.8]], atol=1e-12)
    ff_law = LinearLaw(np.array([1.0, 2.0]), np.zeros(2), np.zeros(2), Memory.FEEDFORWARD)
    np.testing.assert_allclose(ff_law.update(record).feedforward, FEEDFORWARD + [1.0, 2.0] * E)


def test_iterations_to_bound() -> None:
    table = np.array([[0.1, 0.001, 0.1], [0.004, 0.001, 0.1], [0.006, 0.002, 0.004],
                      [0.003, 0.001, 0.1], [0.002, 0.0049, 0.1]])
    result = iterations_to_bound(table, 0.005)
    assert result.first == [2, 1, 3]
    assert result.settled == [4, 1, None]
    assert iterations_to_bound(np.full((3, 1), 0.5), 0.005).first == [None]
