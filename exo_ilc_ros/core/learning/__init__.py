"""What the loop learns between trials: the patient's joint forces (:mod:`.identification`)."""
