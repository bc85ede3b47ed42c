"""Whether a law converges: iterations to the bound, the trial-to-trial factor per frequency,
the growth check of the learned input, norm-optimal's robustness."""
