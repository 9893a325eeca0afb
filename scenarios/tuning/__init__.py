"""Threshold tuning: grid sweeps, Optuna searches over recordings, pool and Ray backends."""
