"""The industrial UGV: its description and its onboard navigation stack (no PyBullet)."""
