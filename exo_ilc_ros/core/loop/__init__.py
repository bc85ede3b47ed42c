"""One trial's closed loop, compiled: the plant under effort (RK4, eq (8)), the controller (eqs
(11), (9)/(16)) and its per-sample rule (error envelope, safe hold), the virtual patient, the
watchdog, and :class:`~exo_ilc_ros.core.loop.record.TrialRecord`, what a trial produced."""
