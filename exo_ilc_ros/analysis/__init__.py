"""What a user reads and looks at: per-trial tables and the JSON export (:mod:`.report`), law
comparisons (:mod:`.comparison`), figures (:mod:`.figures`) and the threshold tuner
(:mod:`.tuning`). Built on the core, and on bags read back; nothing here starts a node."""
