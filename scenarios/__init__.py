"""Experiments: scenario files, the closed-loop runner, metrics, figures and the CLI."""
