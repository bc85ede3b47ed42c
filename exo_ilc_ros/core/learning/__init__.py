"""Learning laws that need no lifted (trial-length squared) matrices."""
