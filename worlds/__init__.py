"""Environments as data: walls, reflective posts, semi-static boxes, people, test pieces, the path.

Examples
--------
>>> from worlds import bundled_worlds, load_world
>>> "pal3" in bundled_worlds()
True
>>> load_world("pal3").people[0].enabled
False
"""

from semistatic.errors import SpecError
from worlds.checks import Clearances, LayoutProblem, layout_problems
from worlds.load import bundled_worlds, load_world
from worlds.spec import (
    BoxSpec,
    PathSpec,
    PersonSpec,
    PostSpec,
    SegmentSpec,
    TestPieceSpec,
    WallSpec,
    WorldSpec,
)

__all__ = [
    "BoxSpec",
    "Clearances",
    "LayoutProblem",
    "PathSpec",
    "PersonSpec",
    "PostSpec",
    "SegmentSpec",
    "SpecError",
    "TestPieceSpec",
    "WallSpec",
    "WorldSpec",
    "bundled_worlds",
    "layout_problems",
    "load_world",
]
