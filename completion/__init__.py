"""colonbench.completion."""
