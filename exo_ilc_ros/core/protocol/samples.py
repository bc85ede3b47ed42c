"""The samples of one trial run elsewhere (the graph, an arm), placed on the control grid by
their stamps: sample i of a trial that starts at t0 is stamped t0 + i * period."""

from __future__ import annotations

import numpy as np

from ..loop.trial import period_ns, sample_index
from ..reference.trajectory import SampledReference


class TrialSamples:
    """q and qdot of the N+1 samples of the running trial (each kept once, by stamp)."""

    def __init__(self, reference: SampledReference) -> None:
        self.step_ns = period_ns(reference.period)
        count, joints = reference.position.shape
        self.position = np.empty((count, joints))
        self.velocity = np.empty((count, joints))
        self.received = np.zeros(count, dtype=bool)
        self.t0_ns = -1
        """Stamp of sample 0 of the running trial (-1: none running)."""

    @property
    def running(self) -> bool:
        """A trial's samples are being collected."""
        return self.t0_ns >= 0

    @property
    def end_ns(self) -> int:
        """Stamp of the trial's last sample."""
        return self.t0_ns + (self.received.shape[0] - 1) * self.step_ns

    @property
    def last_in(self) -> bool:
        """The trial's last sample arrived."""
        return bool(self.received[-1])

    @property
    def missing(self) -> int:
        """Samples not received (of a trial whose last sample is in: lost)."""
        return int((~self.received).sum())

    def start(self, t0_ns: int) -> None:
        """Collect the trial starting at ``t0_ns`` (forgetting any other)."""
        self.t0_ns = int(t0_ns)
        self.received[:] = False

    def stop(self) -> None:
        """Collect nothing until the next :meth:`start`."""
        self.t0_ns = -1

    def add(self, stamp_ns: int, position: np.ndarray, velocity: np.ndarray) -> bool:
        """Keep the sample if it is one of the running trial's and new (True then)."""
        if self.t0_ns < 0:
            return False
        i = sample_index(stamp_ns, self.t0_ns, self.step_ns, self.received.shape[0])
        if i is None or self.received[i]:
            return False
        self.position[i] = position
        self.velocity[i] = velocity
        self.received[i] = True
        return True


class CuffSamples:
    """A person strapped in (``musculoskeletal.model``): the cuffs' wrench (force N, torque
    N m, cuff frame) at every sample of the running trial, each cuff's kept once, by stamp
    (the plant's per-cuff messages, ``wire.topics.CUFF_WRENCHES``)."""

    def __init__(self, reference: SampledReference, cuffs: int) -> None:
        self.step_ns = period_ns(reference.period)
        count = reference.position.shape[0]
        self.wrench = np.full((count, cuffs, 6), np.nan)
        self.received = np.zeros((count, cuffs), dtype=bool)
        self.t0_ns = -1

    def start(self, t0_ns: int) -> None:
        """Collect the trial starting at ``t0_ns`` (forgetting any other)."""
        self.t0_ns = int(t0_ns)
        self.wrench[:] = np.nan
        self.received[:] = False

    def add(self, cuff: int, stamp_ns: int, wrench: np.ndarray) -> bool:
        """Keep cuff ``cuff``'s wrench at the sample stamped ``stamp_ns`` if it is one of the
        running trial's and new (True then)."""
        if self.t0_ns < 0 or not 0 <= cuff < self.received.shape[1]:
            return False
        i = sample_index(stamp_ns, self.t0_ns, self.step_ns, self.received.shape[0])
        if i is None or self.received[i, cuff]:
            return False
        self.wrench[i, cuff] = wrench
        self.received[i, cuff] = True
        return True

    def complete_before(self, sample: int) -> bool:
        """Every cuff's wrench of the samples before ``sample`` is in."""
        return bool(self.received[:sample].all())
