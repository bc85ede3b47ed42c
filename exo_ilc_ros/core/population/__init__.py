"""Patient populations and a law's certificate over them (issue 33; docs/every-patient.md)."""
