"""colonbench.baselines."""
