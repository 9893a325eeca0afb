"""Scenario data: the spec, files and their checks, per-lap layouts, routes and segments."""
