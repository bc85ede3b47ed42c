"""Running the node graph from Python: the processes of a run and their domain
(:mod:`.launcher`), a run through the graph followed to its end (:mod:`.graph`) and its bag
recorder (:mod:`.recording`). What ``exo-ilc run`` and the graph tests drive."""
