"""The command line's commands: check, run, table, replay, evaluate and tune."""
