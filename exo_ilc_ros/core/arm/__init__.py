"""Arms from their URDF: kernel arrays of the chain, a person's arm segments, MuJoCo."""
