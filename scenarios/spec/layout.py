"""The world a scenario's robot drives on each lap: people switched on, boxes moved.

Semi-static objects "change their location [...] while the robot is not observing them"
(paper Sec. 1): a scenario's :class:`~scenarios.spec.scenario.BoxMove` s happen before a lap starts,
while the robot is back at the path start. This module applies them to the world
(``move``, ``add`` and ``remove`` a :class:`~worlds.spec.BoxSpec` by name) and checks that
every resulting layout is still a testbench (:func:`worlds.checks.layout_problems`): a
box moved into a protective field would stop the robot for good, one moved out of every
warning field would never be detected.

Every error is a :class:`~semistatic.errors.SpecError` naming the scenario file and the key
to fix (``moves[2].box``, ``people[0]``, ``world``, ``robot``).

Examples
--------
>>> from worlds.load import load_world
>>> from scenarios.spec.scenario import BoxMove
>>> world = load_world("sim1")
>>> moves = [BoxMove(lap=3, action="remove", box="carton_north")]
>>> [box.name for box in world_for_lap(world, moves, lap=2).boxes]
['carton_aisle', 'pallet_turn', 'carton_north']
>>> [box.name for box in world_for_lap(world, moves, lap=3).boxes]
['carton_aisle', 'pallet_turn']
>>> world_for_lap(world, [BoxMove(lap=2, action="remove", box="carton_nort")], lap=2)
Traceback (most recent call last):
...
semistatic.errors.SpecError: <memory>: moves[0].box: no box named 'carton_nort' in world 'sim1' \
before lap 2 (did you mean 'carton_north'?); boxes then: carton_aisle, pallet_turn, carton_north
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from robots.presets import PRESETS, UGVSpec, get_preset
from scenarios.spec.scenario import BoxMove, ScenarioSpec
from semistatic.errors import MEMORY, SpecError
from semistatic.validation import FILE_KEY, did_you_mean
from worlds.checks import Clearances, LayoutProblem, build_spline, layout_problems
from worlds.load import load_world
from worlds.spec import BoxSpec, WorldSpec

__all__ = [
    "check_first_lap",
    "check_moves",
    "check_scenario_layout",
    "enable_people",
    "estimated_sim_time",
    "lap_worlds",
    "robot_footprint",
    "robot_preset",
    "scenario_world",
    "with_loaded_world",
    "world_for_lap",
]


FIRST_LAP_ORDER = ("solids", "people", "footprint", "protective", "posts", "warning", "static")
"""Which problem of a lap-1 layout is reported first: what cannot stand before the rest."""


def _in_lap_order(moves: Sequence[BoxMove], lap: int) -> list[tuple[int, BoxMove]]:
    """Return ``(index, move)`` for the moves up to ``lap``, by lap then file order."""
    due = [(index, move) for index, move in enumerate(moves) if move.lap <= lap]
    return sorted(due, key=lambda item: (item[1].lap, item[0]))


def _apply(
    boxes: list[BoxSpec], index: int, move: BoxMove, *, world: str, file: str
) -> list[BoxSpec]:
    """Return ``boxes`` (of world ``world``) after ``move``, the scenario's ``index``-th."""
    where = f"moves[{index}]"
    names = [box.name for box in boxes]
    if move.action == "add":
        if move.box in names:
            raise SpecError(
                file,
                f"{where}.box",
                f"a box named {move.box!r} already stands there before lap {move.lap}; "
                'use action = "move" to move it or give the new box another name',
            )
        try:
            added = BoxSpec(move.box, size=move.size, pose=move.pose)
        except SpecError as error:
            raise error.located(file, where) from None
        return [*boxes, added]
    if move.box not in names:
        known = ", ".join(names) if names else "none"
        raise SpecError(
            file,
            f"{where}.box",
            f"no box named {move.box!r} in world {world!r} before lap {move.lap}"
            f"{did_you_mean(move.box, names)}; boxes then: {known}",
        )
    position = names.index(move.box)
    if move.action == "remove":
        for key in ("pose", "size"):
            if getattr(move, key) is not None:
                raise SpecError(file, f"{where}.{key}", "'remove' takes no pose or size")
        return boxes[:position] + boxes[position + 1 :]
    changes = {"pose": move.pose}
    if move.size is not None:
        changes["size"] = move.size
    try:
        moved = dataclasses.replace(boxes[position], **changes)
    except SpecError as error:
        raise error.located(file, where) from None
    return [*boxes[:position], moved, *boxes[position + 1 :]]


def world_for_lap(
    world: WorldSpec, moves: Sequence[BoxMove], lap: int, *, file: str = MEMORY
) -> WorldSpec:
    """Return ``world`` with the boxes where they stand during lap ``lap`` (from 1).

    The moves of laps ``2..lap`` are applied in lap order (file order within a lap): a
    ``move`` replaces a box's pose (and its size when given), ``add`` appends a new box,
    ``remove`` drops one. Errors name ``moves[i]`` (its index in ``moves``) in ``file``.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> from scenarios.spec.scenario import BoxMove
    >>> world = load_world("pal1")
    >>> move = BoxMove(lap=2, action="move", box="carton_west", pose=(2.5, -1.0, 0.0))
    >>> world_for_lap(world, [move], lap=2).boxes[0].pose
    (2.5, -1.0, 0.0)
    >>> world_for_lap(world, [move], lap=1).boxes[0].pose
    (2.0, -1.0, 0.0)
    >>> add = BoxMove(lap=2, action="add", box="carton_west", pose=(1, 1, 0), size=(1, 1, 1))
    >>> world_for_lap(world, [add], lap=2)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: moves[0].box: a box named 'carton_west' already ...
    """
    if isinstance(lap, bool) or not isinstance(lap, int | np.integer) or lap < 1:
        raise ValueError(f"world_for_lap: lap counts from 1, got {lap!r}")
    boxes = list(world.boxes)
    for index, move in _in_lap_order(moves, int(lap)):
        boxes = _apply(boxes, index, move, world=world.name, file=file)
    if boxes == list(world.boxes):
        return world
    return dataclasses.replace(world, boxes=tuple(boxes))


def enable_people(world: WorldSpec, people: Sequence[str], *, file: str = MEMORY) -> WorldSpec:
    """Return ``world`` with the named people switched on; an unknown name names ``people[i]``.

    Examples
    --------
    >>> from worlds.load import load_world
    >>> world = enable_people(load_world("pal3"), ["walker"])
    >>> [person.name for person in world.active_people]
    ['walker']
    >>> enable_people(load_world("pal3"), ["waker"], file="s.toml")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: s.toml: people[0]: world 'pal3' has no person named 'waker' \
(did you mean 'walker'?); people: walker
    """
    known = [person.name for person in world.people]
    for index, name in enumerate(people):
        if name not in known:
            listing = ", ".join(known) if known else "none"
            raise SpecError(
                file,
                f"people[{index}]",
                f"world {world.name!r} has no person named {name!r}"
                f"{did_you_mean(name, known)}; people: {listing}",
            )
    return world.enable_people(*people) if people else world


def _load_world(spec: ScenarioSpec) -> WorldSpec:
    """Return the world ``spec`` carries for its ``world``, else read it; errors name ``world``."""
    if spec.loaded_world is not None and spec.loaded_world[0] == spec.world:
        return spec.loaded_world[1]
    try:
        return load_world(spec.world)
    except SpecError as error:
        if error.file == spec.world and error.key == FILE_KEY:
            looks_like_name = "/" not in spec.world and not spec.world.endswith(".toml")
            message = error.message if looks_like_name else f"{spec.world}: {error.message}"
            raise SpecError(spec.source, "world", message) from None
        raise


def with_loaded_world(spec: ScenarioSpec, world: WorldSpec | None = None) -> ScenarioSpec:
    """Return ``spec`` carrying its world (``world``, else read now unless it carries it).

    Every later use (the checks, each run, in worker processes too) takes that world
    instead of reading the file again; a spec whose ``world`` is replaced reads its own.

    Examples
    --------
    >>> from scenarios.spec.scenario import ScenarioSpec
    >>> spec = with_loaded_world(ScenarioSpec("s", world="pal1"))
    >>> spec.loaded_world[0], spec == ScenarioSpec("s", world="pal1")
    ('pal1', True)
    >>> _load_world(dataclasses.replace(spec, world="sim1")).name
    'sim1'
    """
    world = _load_world(spec) if world is None else world
    return dataclasses.replace(spec, loaded_world=(spec.world, world))


def scenario_world(spec: ScenarioSpec) -> WorldSpec:
    """Return the world of lap 1: loaded, with the scenario's people switched on.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> world = scenario_world(load_scenario("pal3b"))
    >>> world.name, [person.name for person in world.active_people]
    ('pal3', ['walker'])
    """
    return enable_people(_load_world(spec), spec.people, file=spec.source)


def estimated_sim_time(spec: ScenarioSpec, world: WorldSpec | None = None) -> float:
    """Return about how long (simulated s) ``spec`` drives: its laps of the path at speed.

    Stops and slowdowns make a run longer; progress bars and the order of a campaign's
    runs (longest first) need no more than this.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> round(estimated_sim_time(load_scenario("pal1", overrides=["laps=2"])))
    55
    """
    world = scenario_world(spec) if world is None else world
    return spec.laps * build_spline(world.path).length / world.path.speed


def lap_worlds(spec: ScenarioSpec, *, world: WorldSpec | None = None) -> tuple[WorldSpec, ...]:
    """Return the world of every lap, ``lap_worlds(spec)[lap - 1]`` for ``lap`` in 1..laps.

    ``world`` (e.g. a :class:`~worlds.spec.WorldSpec` built in code) replaces the world
    the scenario names; the scenario's people and box moves apply to it.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> worlds = lap_worlds(load_scenario("sim1"))
    >>> len(worlds), [len(world.boxes) for world in worlds]
    (5, [3, 3, 3, 2, 3])
    """
    if world is None:
        world = scenario_world(spec)
    else:
        world = enable_people(world, spec.people, file=spec.source)
    return tuple(
        world_for_lap(world, spec.moves, lap, file=spec.source) for lap in range(1, spec.laps + 1)
    )


def robot_preset(robot: str | UGVSpec, *, file: str = MEMORY) -> UGVSpec:
    """Return robot preset ``robot`` (a spec passes through); an unknown name names ``robot``.

    Examples
    --------
    >>> robot_preset("pioneer3dx").name
    'pioneer3dx'
    >>> robot_preset("pioner3dx", file="s.toml")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: s.toml: robot: unknown robot preset 'pioner3dx' \
(did you mean 'pioneer3dx'?); presets: lgv, pioneer3dx
    """
    if isinstance(robot, UGVSpec):
        return robot
    try:
        return get_preset(robot)
    except KeyError:
        raise SpecError(
            file,
            "robot",
            f"unknown robot preset {robot!r}{did_you_mean(robot, PRESETS)}; "
            f"presets: {', '.join(sorted(PRESETS))}",
        ) from None


def robot_footprint(robot: str, *, file: str = MEMORY) -> np.ndarray:
    """Return the ``(N, 2)`` footprint of robot preset ``robot``; unknown names ``robot``.

    Examples
    --------
    >>> robot_footprint("pioneer3dx").shape
    (4, 2)
    """
    return np.asarray(robot_preset(robot, file=file).footprint, dtype=float)


def _blamed(
    problems: list[LayoutProblem],
    before: list[LayoutProblem],
    lap_moves: list[tuple[int, BoxMove]],
) -> list[tuple[int, LayoutProblem]]:
    """Return ``(move index, problem)`` for each problem the moves of one lap caused.

    A problem counts against the moves when it involves a box they touched, or when it
    is new (the layout before them did not have it): a world's own flaws are not blamed
    on the scenario.
    """
    known = {(problem.check, problem.subject) for problem in before}
    blamed = []
    for problem in problems:
        culprits = [index for index, move in lap_moves if move.box in problem.boxes]
        if culprits:
            blamed.append((culprits[-1], problem))
        elif (problem.check, problem.subject) not in known:
            blamed.append((lap_moves[0][0], problem))
    return blamed


def _world_key(world: WorldSpec, problem: LayoutProblem) -> str:
    """Return the key in the world file of what ``problem`` is about (``boxes[1]``, ...)."""
    for kind, label in (("boxes", "box"), ("people", "person"), ("test_pieces", "test piece")):
        for index, item in enumerate(getattr(world, kind)):
            if problem.subject == f"{label} {item.name!r}":
                return f"{kind}[{index}]"
    if problem.check == "posts":
        return "posts"
    return problem.subject if problem.subject.startswith(("walls[", "posts[")) else "path"


def check_first_lap(
    world: WorldSpec,
    *,
    footprint: np.ndarray,
    clearances: Clearances | None = None,
) -> None:
    """Raise :class:`SpecError` in the world's file if its lap-1 layout is no testbench.

    Lap 1 is the world as written (with the scenario's people): too few posts to
    triangulate from every path pose, a box on a wall, in a protective field or on the
    swept footprint fail here, before any simulation. The problem reported first is the
    most physical one (``FIRST_LAP_ORDER``).

    Examples
    --------
    >>> from worlds.checks import PIONEER_FOOTPRINT
    >>> from worlds.load import load_world
    >>> world = load_world("sim1")
    >>> check_first_lap(world, footprint=PIONEER_FOOTPRINT)
    >>> few_posts = dataclasses.replace(world, posts=world.posts[:2])
    >>> check_first_lap(few_posts, footprint=PIONEER_FOOTPRINT)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: ...sim1.toml: posts: lap 1: path: ... pose(s) see fewer than 3...
    """
    problems = layout_problems(world, footprint=footprint, clearances=clearances)
    problems.sort(key=lambda problem: FIRST_LAP_ORDER.index(problem.check))
    if problems:
        first = problems[0]
        more = f"; and {len(problems) - 1} more problem(s)" if len(problems) > 1 else ""
        raise SpecError(world.source, _world_key(world, first), f"lap 1: {first}{more}")


def check_moves(
    world: WorldSpec,
    moves: Sequence[BoxMove],
    *,
    footprint: np.ndarray,
    file: str = MEMORY,
    clearances: Clearances | None = None,
) -> None:
    """Raise :class:`SpecError` at ``moves[i]`` if the moves leave a lap's layout broken.

    Each lap with moves is checked with :func:`worlds.checks.layout_problems` against the
    lap before it; the error names the move to blame and the problem.

    Examples
    --------
    >>> from worlds.checks import PIONEER_FOOTPRINT
    >>> from worlds.load import load_world
    >>> from scenarios.spec.scenario import BoxMove
    >>> onto_path = BoxMove(lap=2, action="move", box="carton_aisle", pose=(3.0, -0.3, 0.0))
    >>> check_moves(load_world("sim1"), [onto_path], footprint=PIONEER_FOOTPRINT, file="s.toml")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: s.toml: moves[0]: before lap 2: box 'carton_aisle': overlaps a \
protective field (needs a gap of >= 0.05 m); and 1 more problem(s)
    """
    if not moves:
        return
    previous = layout_problems(world, footprint=footprint, clearances=clearances)
    for lap in sorted({move.lap for move in moves}):
        current = world_for_lap(world, moves, lap, file=file)
        problems = layout_problems(current, footprint=footprint, clearances=clearances)
        lap_moves = [(index, move) for index, move in enumerate(moves) if move.lap == lap]
        blamed = _blamed(problems, previous, lap_moves)
        if blamed:
            index, problem = blamed[0]
            more = f"; and {len(blamed) - 1} more problem(s)" if len(blamed) > 1 else ""
            raise SpecError(file, f"moves[{index}]", f"before lap {lap}: {problem}{more}")
        previous = problems


def check_scenario_layout(
    spec: ScenarioSpec,
    *,
    moves: Sequence[BoxMove] | None = None,
    clearances: Clearances | None = None,
    world: WorldSpec | None = None,
    robot: UGVSpec | None = None,
) -> None:
    """Check a scenario's world, robot, people and every lap's layout; raise :class:`SpecError`.

    Lap 1 is checked as it stands (:func:`check_first_lap`), later laps against the lap
    before them (:func:`check_moves`).

    ``moves`` defaults to ``spec.moves``; the loader passes the file's moves when a
    ``--set laps=N`` dropped the later ones, so the whole file is checked. ``world`` (e.g.
    built in code) replaces the world the scenario names and ``robot`` its robot, as
    :class:`~scenarios.bench.testbench.Testbench` does.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> check_scenario_layout(load_scenario("pal3b"))
    >>> spec = load_scenario("pal3b")
    >>> check_scenario_layout(dataclasses.replace(spec, world="pal2"))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: ...pal3b.toml: world: not a bundled world (did you mean 'pal3'?) \
and no such file; bundled worlds: ...
    """
    if robot is None:
        footprint = robot_footprint(spec.robot, file=spec.source)
    else:
        footprint = np.asarray(robot.footprint, dtype=float)
    if world is None:
        world = scenario_world(spec)
    else:
        world = enable_people(world, spec.people, file=spec.source)
    check_first_lap(world, footprint=footprint, clearances=clearances)
    check_moves(
        world,
        spec.moves if moves is None else moves,
        footprint=footprint,
        file=spec.source,
        clearances=clearances,
    )
