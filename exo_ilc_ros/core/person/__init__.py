"""The person in the exoskeleton: a musculoskeletal model (MuJoCo muscles), its neural drive
and the stretch test that calibrates it."""
