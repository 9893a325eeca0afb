"""Speed measurements (``pytest -m bench benchmarks``): figures are printed, never asserted."""
