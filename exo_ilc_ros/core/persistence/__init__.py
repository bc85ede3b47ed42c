"""What is kept on disk, never half-written: the store of a run's trials, patients' learned
profiles and the learning patient's states, atomic files and locks."""
