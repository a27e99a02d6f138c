"""colonbench.datagen."""
