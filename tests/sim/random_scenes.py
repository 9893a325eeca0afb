"""Seeded random worlds of boxes and posts for the simulator tests (no PyBullet here)."""

from __future__ import annotations

import math

import numpy as np
import shapely

from sim.ground_truth import obstacle_footprints
from worlds.spec import BoxSpec, PathSpec, PostSpec, SegmentSpec, WallSpec, WorldSpec

FIELD = ((0.3, -0.3), (0.6, -0.3), (0.6, 0.3), (0.3, 0.3))
HALF_ROOM = 9.0


def simple_path() -> PathSpec:
    """Return a valid one-segment path (the worlds' validation needs one)."""
    return PathSpec(((0.0, 0.0), (1.0, 0.0)), (SegmentSpec("a", 0, 1, FIELD, FIELD),))


def room_walls(half: float = HALF_ROOM) -> tuple[WallSpec, ...]:
    """Return four walls enclosing the square [-half, half]^2."""
    corners = [(-half, -half), (half, -half), (half, half), (-half, half)]
    return tuple(WallSpec(corners[i], corners[(i + 1) % 4]) for i in range(4))


def random_world(rng: np.random.Generator, *, walls: bool, name: str = "random") -> WorldSpec:
    """Return a world of 3-8 random boxes and 2-6 random posts inside a 16 m square."""
    boxes = tuple(
        BoxSpec(
            f"box_{index}",
            (rng.uniform(0.2, 1.5), rng.uniform(0.2, 1.5), rng.uniform(0.5, 1.5)),
            (rng.uniform(-7.5, 7.5), rng.uniform(-7.5, 7.5), rng.uniform(-math.pi, math.pi)),
            remission=rng.uniform(0.1, 0.5),
        )
        for index in range(rng.integers(3, 9))
    )
    posts: list[PostSpec] = []
    while len(posts) < rng.integers(2, 7):
        candidate = PostSpec(
            rng.uniform(-7.5, 7.5), rng.uniform(-7.5, 7.5), radius=rng.uniform(0.03, 0.4)
        )
        if all(
            math.dist(candidate.xy, post.xy) > candidate.radius + post.radius + 0.01
            for post in posts
        ):
            posts.append(candidate)
    return WorldSpec(
        name=name,
        walls=room_walls() if walls else (),
        posts=tuple(posts),
        boxes=boxes,
        people=(),
        path=simple_path(),
    )


def free_pose(
    rng: np.random.Generator, world: WorldSpec, z: float, clearance: float = 0.3
) -> np.ndarray:
    """Return a random (x, y, z, yaw) sensor pose at least ``clearance`` from every obstacle."""
    obstacles = shapely.union_all(list(obstacle_footprints(world).values()))
    while True:
        x, y = rng.uniform(-7.0, 7.0, 2)
        if obstacles.distance(shapely.Point(x, y)) > clearance:
            return np.array([x, y, z, rng.uniform(-math.pi, math.pi)])
