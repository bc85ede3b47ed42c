"""The learning laws behind one interface (the sign law of eqs (11)-(13) with the schedules of
(22)-(24), the linear law, norm-optimal ILC, the Q-filter, assist-as-needed), the law factory,
and the identification of the patient's joint forces between trials."""
