"""The reference a trial tracks: the quintic of eq (14), exercises through rest points."""
