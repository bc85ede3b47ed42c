"""What runs many sessions: therapy sessions and their metrics, the robustness study, the spread
of iterations to the bound."""
