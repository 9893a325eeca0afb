"""Results of runs: metrics, the output directory, Table 1 and the figures."""
