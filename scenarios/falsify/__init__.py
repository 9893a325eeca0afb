"""Falsification: search scenario variations for where a field policy fails."""
