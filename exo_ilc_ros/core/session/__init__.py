"""The learning session (trial -> learn, keep or run again; live changes; resume), the
in-process runner :func:`~exo_ilc_ros.core.session.learning_session.run_trials` and a run's
result and summary."""
