"""Environments as data: walls, reflective posts, semi-static boxes, people, the path."""
