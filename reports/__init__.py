"""colonbench.reports: leaderboard tables and figures rebuilt from stored benchmark runs."""
