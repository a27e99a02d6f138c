"""colonbench.benchmark."""
