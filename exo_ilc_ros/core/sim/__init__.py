"""The experiment in-process (:class:`~exo_ilc_ros.core.sim.experiment.Experiment`: config ->
nominal model, plant, reference, gains, patient; one trial) and the arm in MuJoCo."""
