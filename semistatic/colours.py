"""One palette for every view of a run: the GUI, recordings, bags and figures.

A local-map polyline is drawn in the colour of its life-cycle status, the safety fields
in the colours a scanner's configuration tool uses (warning orange, protective red), so a
user who learnt them in one view reads the others. Colours are RGB triples in [0, 1];
:func:`rgba8` converts one for viewers that take 8-bit RGBA (Rerun, ROS markers take
floats).

Examples
--------
>>> STATUS_COLOURS["confirmed"]
(0.0, 0.65, 0.0)
>>> rgba8(FIELD_COLOURS["protective"])
(230, 0, 0, 255)
"""

from __future__ import annotations

__all__ = [
    "BOX_COLOUR",
    "EKF_COLOUR",
    "FIELD_COLOURS",
    "PERSON_COLOUR",
    "POLYLINE_COLOUR",
    "POST_COLOUR",
    "RETURNS_COLOUR",
    "STATUS_COLOURS",
    "TEXT_COLOUR",
    "TRUE_COLOUR",
    "WALL_COLOUR",
    "Colour",
    "rgba8",
]

Colour = tuple[float, float, float]

STATUS_COLOURS: dict[str, Colour] = {
    "new": (0.1, 0.45, 1.0),
    "confirmed": (0.0, 0.65, 0.0),
    "blank": (0.55, 0.55, 0.55),
}
"""A local-map polyline by its life-cycle status (:mod:`semistatic.local_map`)."""

POLYLINE_COLOUR: Colour = (0.9, 0.8, 0.1)
"""A map polyline whose status is not known (a ROS bag frame written without statuses)."""

FIELD_COLOURS: dict[str, Colour] = {
    "warning": (1.0, 0.6, 0.0),
    "protective": (0.9, 0.0, 0.0),
    "minimum": (0.5, 0.0, 0.0),
}
"""The safety fields: warning, protective, and the minimum protective field."""

RETURNS_COLOUR: Colour = (0.75, 0.0, 0.75)
"""Safety-laser returns."""

WALL_COLOUR: Colour = (0.25, 0.25, 0.25)
POST_COLOUR: Colour = (0.0, 0.6, 0.6)
BOX_COLOUR: Colour = (0.6, 0.4, 0.2)
PERSON_COLOUR: Colour = (1.0, 0.1, 0.6)
TRUE_COLOUR: Colour = (0.1, 0.1, 0.1)
EKF_COLOUR: Colour = (0.0, 0.55, 0.9)
"""The static world, true boxes and people, and the true and EKF trajectories."""

TEXT_COLOUR: Colour = (0.05, 0.05, 0.2)
"""Labels and status text (the GUI's legend and status line)."""


def rgba8(colour: Colour, alpha: float = 1.0) -> tuple[int, int, int, int]:
    """Return ``colour`` with ``alpha`` as 8-bit RGBA.

    Examples
    --------
    >>> rgba8((1.0, 0.5, 0.0), alpha=0.5)
    (255, 128, 0, 128)
    """
    return tuple(round(255 * channel) for channel in (*colour, alpha))
