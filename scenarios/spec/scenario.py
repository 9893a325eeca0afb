"""What a scenario file describes, as frozen dataclasses (no I/O, no simulator).

A scenario is one experiment: a world, a robot preset, how many laps, the seed, the sensor
rates and noise, the box moves between laps, which people walk, the mapper thresholds
and the safety-field policy. ``scenarios.spec.load`` builds these from TOML with the same
validation layer as the worlds (unknown keys rejected with a suggestion, file and key
named in every error).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

from semistatic.errors import MEMORY, SpecError
from semistatic.params import MapperParams
from semistatic.validation import bounds, check_fields, did_you_mean, or_object, safe_name
from worlds.spec import BOX_SIZE, COORDINATE, WorldSpec

__all__ = [
    "BOX_ACTIONS",
    "LOADER_FIELDS",
    "POLICIES",
    "BoxMove",
    "Faults",
    "Noise",
    "Rates",
    "SafetySettings",
    "ScenarioSpec",
    "VehicleSpec",
]

MAX_LAPS = 1000
"""Laps of one run: 1000 laps of a 10 m path are about 10 km, a few days of driving."""

MAX_SEED = 2**63 - 1
"""Largest seed (a 64-bit signed integer, what every tool around us can store)."""

MAX_LAP_TIMEOUT = 3600.0
"""Longest lap timeout (s): a lap of a bundled path takes 25-60 s."""

MAX_SCANNER_LATENCY = 2.0
"""Longest seeded scanner latency (s): a dozen scans of a 12.5 Hz scanner, far past any field."""

MAX_START_TIME = 3600.0
"""Latest start of a fleet vehicle (s): an hour of the others driving alone."""

POLICIES = ("conservative", "adaptive", "guarded")

LOADER_FIELDS = ("source", "loaded_world")
"""Fields of :class:`ScenarioSpec` the loaders set: where it came from, never keys of a file
and no part of what a run is (fingerprints and digests leave them out)."""
BOX_ACTIONS = ("move", "add", "remove")


@dataclass(frozen=True)
class Rates:
    """Update rates in Hz. Physics steps at ``physics_hz``; everything else is scheduled on it.

    The defaults follow the design page (docs/design.md): 240 Hz physics, 50 Hz control, a
    25 Hz localization laser (LMS100 runs at 25 or 50 Hz) and a 12.5 Hz safety laser (S300,
    80 ms scan time). With the ``pioneer3dx`` preset one LMS100 serves both roles; each role
    then uses its own rate.

    Parameters
    ----------
    physics_hz
        Physics steps per second (Hz); every other rate is scheduled on it.
    control_hz
        Follower commands per second (Hz).
    localization_hz
        Scans of the localization laser per second (Hz).
    safety_hz
        Scans of the safety laser per second (Hz); each also updates the map.
    """

    physics_hz: float = field(default=240.0, metadata=bounds(ge=60.0, le=2000.0))
    control_hz: float = field(default=50.0, metadata=bounds(gt=0.0, le=500.0))
    localization_hz: float = field(default=25.0, metadata=bounds(gt=0.0, le=100.0))
    safety_hz: float = field(default=12.5, metadata=bounds(gt=0.0, le=100.0))

    def __post_init__(self) -> None:
        check_fields(self)
        for name in ("control_hz", "localization_hz", "safety_hz"):
            if getattr(self, name) > self.physics_hz:
                raise SpecError(
                    MEMORY, name, f"must not exceed physics_hz ({self.physics_hz:g} Hz)"
                )


@dataclass(frozen=True)
class Noise:
    """Scale factors on the robot preset's noise models (1.0 = the data-sheet values).

    Parameters
    ----------
    odometry
        Factor on the wheel-encoder slip noise (0 = noise-free odometry).
    range
        Factor on the lasers' range noise (0 = exact ranges).
    """

    odometry: float = field(default=1.0, metadata=bounds(ge=0.0, le=100.0))
    range: float = field(default=1.0, metadata=bounds(ge=0.0, le=100.0))

    def __post_init__(self) -> None:
        check_fields(self)


MINIMUM_FIELDS = ("standard", "fixed")
"""How the minimum protective field (what no field policy may shrink) is drawn."""


@dataclass(frozen=True)
class SafetySettings:
    """The safety supervisor and the field policy.

    ``slowdown`` is the speed factor while the warning field is occupied; the protective
    field stops the robot. ``release_delay`` (s) keeps the reaction after the field clears.
    ``min_points`` readings must fall in a field before it counts (one noisy beam is
    ignored). Under the ``adaptive`` policy, readings within ``adaptive_margin`` (m) of a
    known semi-static object of the current segment no longer count. Whatever the policy,
    every reading in the *minimum protective field* counts: with ``minimum_field =
    "standard"`` the field the standard's formula asks for at the measured speed, and the
    footprint grown by the laser's general supplement (:mod:`scenarios.bench.fields`);
    ``"fixed"`` keeps only the first ``min_protective_depth`` (m) of the segment's
    protective field, to study what that misses. A protective field shorter or narrower
    than the formula asks for at the segment's speed is refused
    (:mod:`scenarios.spec.field_sizing`) unless ``undersized_fields`` says the scenario
    studies such fields; so is a world's test piece that a vehicle's safety laser scans
    over (:mod:`scenarios.spec.pieces`) unless ``unseen_test_pieces`` does.

    Parameters
    ----------
    slowdown
        Speed factor while the warning field is occupied.
    release_delay
        Time (s) a reaction lasts after its field clears.
    min_points
        Readings that must fall in a field before it counts.
    adaptive_margin
        Distance (m) from a known object within which readings no longer count (adaptive).
    minimum_field
        ``standard`` (sized by the formula at the measured speed) or ``fixed``.
    min_protective_depth
        Depth (m) of the protective field kept whole with ``minimum_field = "fixed"``.
    undersized_fields
        Run protective fields shorter than the formula asks for (their margins are
        reported) instead of refusing them.
    near_miss_distance
        A person closer than this (m) to the vehicle, without contact, is a near miss.
    creep_speed
        Speed (m/s) above which a vehicle with a person in its protective field counts as
        moving (an infraction once it lasts longer than the scanner's response time).
    unseen_test_pieces
        Run worlds with test pieces some vehicle's safety laser scans over (reported by
        ``semistatic check`` and in metrics.json) instead of refusing them.
    """

    slowdown: float = field(default=0.4, metadata=bounds(gt=0.0, le=1.0))
    release_delay: float = field(default=0.5, metadata=bounds(ge=0.0, le=10.0))
    min_points: int = field(default=3, metadata=bounds(ge=1, le=100))
    adaptive_margin: float = field(default=0.10, metadata=bounds(gt=0.0, le=1.0))
    minimum_field: str = "standard"
    min_protective_depth: float = field(default=0.15, metadata=bounds(gt=0.0, le=2.0))
    undersized_fields: bool = False
    near_miss_distance: float = field(default=0.2, metadata=bounds(gt=0.0, le=5.0))
    creep_speed: float = field(default=0.1, metadata=bounds(ge=0.0, le=2.0))
    unseen_test_pieces: bool = False

    def __post_init__(self) -> None:
        check_fields(self)
        if self.minimum_field not in MINIMUM_FIELDS:
            hint = did_you_mean(self.minimum_field, MINIMUM_FIELDS)
            raise SpecError(MEMORY, "minimum_field", f"must be one of "
                            f"{', '.join(MINIMUM_FIELDS)}, got {self.minimum_field!r}{hint}")


@dataclass(frozen=True)
class Faults:
    """Seeded faults of the vehicle's safety chain (table ``[faults]``), all off by default.

    Faults are for studying failures, e.g. as the target of a falsification search: each
    breaks one link of the chain the field sizing relies on. The sizing check
    (:mod:`scenarios.spec.field_sizing`) deliberately ignores them and still sizes the
    fields by the nominal response time and deceleration, so a faulty vehicle drives
    fields that are too small for it; the safety record reports what then happens (every
    contact is a contact). With every fault off a run is the same as without the table.

    Parameters
    ----------
    scanner_latency_s
        Extra delay (s) before the safety scanner's decision (zone, stop, slowdown)
        reaches the vehicle, on top of the modelled response time: a delay line of
        ``scanner_latency_s * safety_hz`` safety scans, to the nearest scan. The sized
        response time
        (``multiple_sampling`` scan periods) doubles the scanner's response.
    braking_factor
        Share of the deceleration the field sizing assumes that the vehicle brakes with
        (1: the nominal brakes).
    unguarded_minimum_field
        The minimum protective field no longer counts every reading inside it: the field
        policy alone decides (the ``adaptive`` policy then ignores a reading near a mapped
        object even right in front of the vehicle).

    Examples
    --------
    >>> Faults().active()
    {}
    >>> Faults(scanner_latency_s=0.16, unguarded_minimum_field=True).active()
    {'scanner_latency_s': 0.16, 'unguarded_minimum_field': True}
    >>> Faults(braking_factor=0.0)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: braking_factor: must be > 0.0 and <= 1.0, got 0.0
    """

    scanner_latency_s: float = field(default=0.0, metadata=bounds(ge=0.0,
                                                                  le=MAX_SCANNER_LATENCY))
    braking_factor: float = field(default=1.0, metadata=bounds(gt=0.0, le=1.0))
    unguarded_minimum_field: bool = False

    def __post_init__(self) -> None:
        check_fields(self)

    def active(self) -> dict[str, float | bool]:
        """Return the faults switched on, by key, with their values (empty: none)."""
        return {item.name: getattr(self, item.name) for item in fields(self)
                if getattr(self, item.name) != item.default}


@dataclass(frozen=True)
class BoxMove:
    """A change to the semi-static boxes before lap ``lap`` starts (laps count from 1).

    ``action`` is ``move`` (needs ``pose``), ``add`` (needs ``pose`` and ``size``) or
    ``remove``. Moves happen while the robot is back at the start, i.e. not observing.

    Parameters
    ----------
    lap
        The lap before which the change happens (2 or later).
    action
        ``move``, ``add`` or ``remove``.
    box
        Name of the box (a new name for ``add``).
    pose
        ``[x, y, yaw]`` of the box centre (m, m, rad), for ``move`` and ``add``.
    size
        ``[sx, sy, sz]`` edges of the box (m); required for ``add``, optional for ``move``.
    """

    lap: int = field(metadata=bounds(ge=2, le=MAX_LAPS))
    action: str
    box: str = field(metadata=safe_name())
    pose: tuple[float, float, float] | None = field(default=None, metadata=COORDINATE)
    size: tuple[float, float, float] | None = field(default=None, metadata=BOX_SIZE)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.action not in BOX_ACTIONS:
            raise SpecError(MEMORY, "action", f"must be one of {', '.join(BOX_ACTIONS)}")
        if self.action in ("move", "add") and self.pose is None:
            raise SpecError(MEMORY, "pose", f"'{self.action}' needs pose = [x, y, yaw]")
        if self.action == "add" and self.size is None:
            raise SpecError(MEMORY, "size", "'add' needs size = [sx, sy, sz]")


@dataclass(frozen=True)
class VehicleSpec:
    """One vehicle of a fleet (array of tables ``[[vehicles]]``).

    Every vehicle drives a route through the world's path segments with its own sensors,
    encoders, EKF, follower, safety supervisor, local maps and random streams. Its laps
    start and end where it starts: at the start of segment ``start_segment`` (a start
    offset along the route, so a closed route can carry vehicles spread round the loop)
    or of the first segment of ``route``. It stands there until ``start_time``.

    Parameters
    ----------
    name
        Name of the vehicle (a key of ``metrics.json``'s ``vehicles``).
    robot
        Robot preset (default: the scenario's ``robot``).
    start_segment
        Name of the path segment at whose start the vehicle starts (default: the first).
    route
        Names of the world's path segments the vehicle drives, in driving order, each
        starting where the one before ends (default: the whole path). Every segment of a
        closed path makes a closed loop driven lap after lap; fewer make an open route,
        after which the vehicle is carried back to its start like on an open path. Give
        ``route`` or ``start_segment``, not both.
    start_time
        Simulated time (s) until which the vehicle stands at its start; its first lap
        starts then.

    Examples
    --------
    >>> VehicleSpec("lgv2", start_segment="north_east").robot
    ''
    >>> VehicleSpec("lgv3", route=("east", "north_east"), start_time=20.0).route
    ('east', 'north_east')
    >>> VehicleSpec("lgv3", start_time=-1.0)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: start_time: ...
    >>> VehicleSpec("lgv 2")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: <memory>: name: ...
    """

    name: str = field(metadata=safe_name())
    robot: str = ""
    start_segment: str = ""
    route: tuple[str, ...] = ()
    start_time: float = field(default=0.0, metadata=bounds(ge=0.0, le=MAX_START_TIME))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.route and self.start_segment:
            raise SpecError(MEMORY, "start_segment",
                            "give route (its first segment is the start) or start_segment, "
                            "not both")


@dataclass(frozen=True)
class ScenarioSpec:
    """One experiment. ``world`` is a bundled world name or a path (relative to the file).

    Parameters
    ----------
    name
        Name of the experiment (default: the file's stem); results go to
        ``results/NAME``, so it is a plain name, not a path.
    world
        A bundled world name or a ``.toml`` path, relative to the scenario file.
    robot
        Robot preset: ``pioneer3dx`` or ``lgv``.
    laps
        Laps to drive.
    seed
        Seed of every random stream (noise, people).
    policy
        Safety-field policy: ``conservative``, ``adaptive`` (the paper's) or ``guarded``
        (docs/safety/index.md; in code, also a ``scenarios.bench.policies.FieldPolicy`` object).
    description
        Free text.
    people
        Names of the world's people to switch on.
    lap_timeout
        Simulated time (s) after which a lap that has not reached the path end fails.
    sharing
        Publish each segment's local map to a fleet map store when the vehicle leaves
        the segment, and report the traffic (``metrics.json`` key ``sharing``).
    rates
        Update rates (table ``[rates]``).
    noise
        Noise scale factors (table ``[noise]``).
    safety
        Safety supervisor and field policy (table ``[safety]``).
    faults
        Seeded faults of the safety chain, all off by default (table ``[faults]``).
    mapper
        Mapper thresholds (table ``[mapper]``).
    moves
        Box changes between laps (array of tables ``[[moves]]``).
    vehicles
        The vehicles of a fleet (array of tables ``[[vehicles]]``); none: one vehicle,
        ``robot``, starting at the path start. With several vehicles, a lap's box moves
        happen when the first vehicle starts that lap; a vehicle is a dynamic obstacle
        for the others (their lasers see it, their protective fields stop for it, their
        mappers leave it out).
    source
        Set by the loader to the file read; not a key of the file.
    loaded_world
        Set by the loader: ``(world, WorldSpec)``, the world as read at the start for
        the ``world`` value it was read for (:func:`scenarios.spec.layout.with_loaded_world`),
        so that every run of a command (in worker processes too) uses that one read of
        the file; ignored once ``world`` names another. Not a key of the file; left out
        of ``==``, ``hash`` and ``repr``.
    """

    name: str = field(metadata=safe_name())
    world: str
    robot: str = "pioneer3dx"
    laps: int = field(default=5, metadata=bounds(ge=1, le=MAX_LAPS))
    seed: int = field(default=0, metadata=bounds(ge=0, le=MAX_SEED))
    # In code, also a scenarios.bench.policies.FieldPolicy object.
    policy: str = field(default="conservative", metadata=or_object())
    description: str = ""
    people: tuple[str, ...] = ()
    lap_timeout: float = field(default=120.0, metadata=bounds(gt=0.0, le=MAX_LAP_TIMEOUT))
    sharing: bool = False
    rates: Rates = field(default_factory=Rates)
    noise: Noise = field(default_factory=Noise)
    safety: SafetySettings = field(default_factory=SafetySettings)
    faults: Faults = field(default_factory=Faults)
    mapper: MapperParams = field(default_factory=MapperParams)
    moves: tuple[BoxMove, ...] = ()
    vehicles: tuple[VehicleSpec, ...] = ()
    source: str = MEMORY
    loaded_world: tuple[str, WorldSpec] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.loaded_world is not None and not (
                isinstance(self.loaded_world, tuple) and len(self.loaded_world) == 2
                and isinstance(self.loaded_world[1], WorldSpec)):
            raise SpecError(MEMORY, "loaded_world", "must be (world, WorldSpec) or None; "
                            "attach it with scenarios.spec.layout.with_loaded_world")
        # A policy object (scenarios.bench.policies.FieldPolicy) is checked when a run starts.
        if isinstance(self.policy, str) and self.policy not in POLICIES:
            raise SpecError(MEMORY, "policy", f"must be one of {', '.join(POLICIES)}")
        for index, move in enumerate(self.moves):
            if move.lap > self.laps:
                raise SpecError(
                    MEMORY,
                    f"moves[{index}].lap",
                    f"lap {move.lap} never runs with laps = {self.laps}",
                )
        names = [vehicle.name for vehicle in self.vehicles]
        for index, name in enumerate(names):
            if name in names[:index]:
                raise SpecError(MEMORY, f"vehicles[{index}].name",
                                f"vehicle {name!r} is named twice; give each a name of its own")
