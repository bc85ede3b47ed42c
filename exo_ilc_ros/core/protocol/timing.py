"""The graph protocol's timing (:mod:`.graph`): how long a step may take, when a push is
repeated, how many late reruns stop a run."""

from __future__ import annotations

STEP_TIMEOUT = 30.0
"""Wall seconds a protocol step may take before the trial is discarded and run again."""


ACK_RETRY = 0.25
"""Wall seconds without the controller's acknowledgement of a pushed feed-forward before it is
pushed again (a lost profile or acknowledgement costs a quarter second, not STEP_TIMEOUT)."""


LATE_RERUNS = 3
"""A real-time trial run again this many times in a row for late commands stops the run: the
machine cannot keep this control rate (nothing stored is lost; resume at a lower rate)."""


RECORDER_TIMEOUT = 5.0
"""Wall seconds to wait for the recorder to file a trial before going on without it."""
