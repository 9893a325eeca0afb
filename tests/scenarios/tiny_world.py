"""A tiny world and scenario for fast closed-loop tests: a 3.5 m path, one box.

``write_crossing`` adds a person who, in lap 3 only, steps out past the box into the lane
when the robot comes (the warm-start tests vary how far ahead and how fast).
"""

from pathlib import Path

TINY_WORLD = """
name = "tiny"
description = "3.5 m corridor with one carton reaching into the warning field"
# The Pioneer at 0.4 m/s: the protective field is the standard's size (0.59 m ahead of the
# bumper, 1.28 m wide with the reflector supplement: posts stand within 1 m of it).
# The end walls stand 2.5 m beyond the path so the swept warning field never reaches them.
walls = [
    { start = [-2.5, -1.5], end = [6.5, -1.5] },
    { start = [-2.5, 1.5], end = [6.5, 1.5] },
    { start = [-2.5, -1.5], end = [-2.5, 1.5] },
    { start = [6.5, -1.5], end = [6.5, 1.5] },
]
# Posts on both sides and at both ends: a geometry that does not favour one direction.
posts = [
    { x = -2.0, y = -1.39 }, { x = 0.0, y = -1.39 }, { x = 2.0, y = -1.39 },
    { x = 4.0, y = -1.39 }, { x = 6.0, y = -1.39 },
    { x = -1.0, y = 1.39 }, { x = 1.0, y = 1.39 }, { x = 3.0, y = 1.39 }, { x = 5.0, y = 1.39 },
    { x = -2.39, y = 0.3 }, { x = 6.39, y = -0.3 },
]

[path]
speed = 0.4
knots = [[0.0, 0.0], [1.75, 0.0], [3.5, 0.0]]

[[path.segments]]
name = "corridor"
start_knot = 0
end_knot = 2
warning = [[0.18, -0.9], [1.4, -0.9], [1.4, 0.9], [0.18, 0.9]]
protective = [[0.18, -0.65], [0.78, -0.65], [0.78, 0.65], [0.18, 0.65]]

[[boxes]]
name = "carton"
size = [0.5, 0.4, 0.6]
pose = [2.6, -1.0, 0.0]
"""

TINY_SCENARIO = """
world = "tiny_world.toml"
laps = 2
seed = 3

[mapper]
hausdorff_restriction = "projection"
"""


def write_tiny(folder: Path, *, scenario: str = TINY_SCENARIO) -> Path:
    """Write the tiny world and scenario into ``folder``; return the scenario path."""
    (folder / "tiny_world.toml").write_text(TINY_WORLD)
    path = folder / "tiny.toml"
    path.write_text(scenario)
    return path


CROSSER = """
[[people]]
name = "crosser"
waypoints = [[3.1, -1.2], [3.1, 1.0]]
radius = 0.2
trigger = "distance"
trigger_distance = {trigger_distance}
speed = {speed}
laps = [3]
"""

CROSSING_SCENARIO = TINY_SCENARIO.replace("laps = 2", "laps = 3")


def write_crossing(folder: Path, *, trigger_distance: float = 2.0, speed: float = 1.0,
                   name: str = "tiny_world") -> Path:
    """Write the tiny world with the lap-3 crosser as ``NAME.toml`` and a 3-lap scenario
    on it as ``NAME_scenario.toml``; return the scenario path."""
    world = TINY_WORLD.replace('name = "tiny"', f'name = "tiny"\n# variant {name}')
    (folder / f"{name}.toml").write_text(
        world + CROSSER.format(trigger_distance=trigger_distance, speed=speed))
    path = folder / f"{name}_scenario.toml"
    path.write_text(CROSSING_SCENARIO.replace("tiny_world.toml", f"{name}.toml"))
    return path
