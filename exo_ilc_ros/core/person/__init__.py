"""A person with muscles in the exoskeleton: MyoSuite's musculoskeletal arm models (``model``),
the exoskeleton strapped to them in cuffs (``strapped``), the neural drive of the muscles and the
stretch test."""
