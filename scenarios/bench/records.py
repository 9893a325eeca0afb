"""What a closed-loop run records: per lap, per scan and for the whole run.

:class:`~scenarios.bench.testbench.Testbench` fills these as it runs;
``scenarios.results.metrics`` and ``scenarios.results.outputs`` turn them into numbers and
files, ``scenarios.logs.bag`` into a ROS 2 bag.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robots.presets import UGVSpec
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment
from semistatic.local_map import LocalMap
from semistatic.mapper import UpdateReport
from semistatic.types import Scan
from worlds.spec import WorldSpec

__all__ = ["AppliedFields", "LapLog", "RunLog", "ScanRecord", "combine_logs"]


@dataclass
class LapLog:
    """What happened in one lap (robot-side figures; scoring observers add the rest).

    Examples
    --------
    >>> log = LapLog(lap=2, start_time=30.0)
    >>> log.completed, log.stops, log.detection
    (False, 0, {})
    """

    lap: int
    start_time: float
    first_tick: int = 0
    duration_s: float = 0.0
    completed: bool = False
    stops: int = 0
    slowdowns: int = 0
    collisions: int = 0
    safety_scans: int = 0
    stopped_time_s: float = 0.0
    slowed_time_s: float = 0.0
    detection: dict = field(default_factory=dict)
    false_objects_from_people: int = 0
    false_objects_from_vehicles: int | None = None  # scored in a fleet only
    latencies: dict[str, int | None] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class AppliedFields:
    """The safety fields as one scan was judged against them, robot frame (x ahead, y left).

    Parameters
    ----------
    warning, protective
        The segment's warning and protective field polygons, ``(N, 2)`` each.
    minimum
        The outline ``(M, 2)`` of the minimum protective field at the measured speed:
        readings inside it count whatever the policy answers (``(0, 2)`` with the seeded
        fault ``faults.unguarded_minimum_field``).
    ignored
        ``(K, 2)`` readings the field policy did not count for the protective field
        (the adaptive policies' readings explained by the local map).
    zone
        The supervisor's zone after the scan: ``clear``, ``warning`` or ``protective``.
    speed_scale
        The speed factor that reached the vehicle (1 free, 0 stopped).

    Examples
    --------
    >>> square = np.array([[0.0, -0.5], [1.0, -0.5], [1.0, 0.5], [0.0, 0.5]])
    >>> fields = AppliedFields(warning=2 * square, protective=square, minimum=square / 2,
    ...                        ignored=np.zeros((0, 2)), zone="clear", speed_scale=1.0)
    >>> fields.zone, fields.minimum.shape
    ('clear', (4, 2))
    """

    warning: np.ndarray
    protective: np.ndarray
    minimum: np.ndarray
    ignored: np.ndarray
    zone: str
    speed_scale: float


@dataclass(frozen=True, eq=False)
class ScanRecord:
    """What the robot knew when one safety-laser scan reached the mapper (for recording).

    Parameters
    ----------
    lap
        The lap, counted from 1.
    segment
        Name of the path segment whose local map the scan updated.
    scan
        The safety-laser scan; its ``pose`` is the simulator's true sensor pose.
    odom_pose
        ``(x, y, theta)`` of the robot from wheel odometry alone, world frame: the
        increments the EKF predicts with, integrated from the triangulated pose at the
        lap start, so it drifts as a real robot's odometry does.
    ekf_pose, ekf_covariance
        The EKF's robot pose (world frame) and its ``(3, 3)`` covariance over
        ``(x, y, theta)``: the pose the mapper placed the scan with.
    polylines
        The current segment's local map after this scan, world frame, ``(N, 2)`` each.
    sensor_pose
        The safety laser's pose from the EKF (world frame): where the mapper placed
        the scan. ``None`` when unknown.
    report
        The :class:`~semistatic.mapper.UpdateReport` of the local-map update (its scan
        polylines are in the segment frame), or ``None``.
    polyline_status
        The life-cycle status of each of ``polylines`` (``new``, ``confirmed`` or
        ``blank``), in the same order.
    fields
        The :class:`AppliedFields` the scan was judged against, or ``None`` (a replayed
        real log has no safety fields).

    Examples
    --------
    >>> scan = Scan(ranges=[1.0, 2.0], angle_min=0.0, angle_increment=0.1, stamp=0.5)
    >>> record = ScanRecord(lap=1, segment="corridor", scan=scan, odom_pose=np.zeros(3),
    ...                     ekf_pose=np.zeros(3), ekf_covariance=np.eye(3) * 1e-4,
    ...                     polylines=(np.array([[0.0, 1.0], [2.0, 1.0]]),))
    >>> record.segment, len(record.polylines)
    ('corridor', 1)
    """

    lap: int
    segment: str
    scan: Scan
    odom_pose: np.ndarray
    ekf_pose: np.ndarray
    ekf_covariance: np.ndarray
    polylines: tuple[np.ndarray, ...] = ()
    sensor_pose: np.ndarray | None = None
    report: UpdateReport | None = None
    polyline_status: tuple[str, ...] = ()
    fields: AppliedFields | None = None


@dataclass
class RunLog:
    """Everything a run recorded; ``scenarios.results.metrics`` turns it into numbers.

    The robot's side (poses, laps, maps after each lap, timings) is filled by the
    :class:`~scenarios.bench.testbench.Testbench`; ``table1_distances``, ``reference_maps``
    and ``example_pair`` by :class:`~scenarios.bench.scoring.Table1Reference`, the lap logs'
    detection figures and ``truth_after_lap`` by
    :class:`~scenarios.bench.scoring.GroundTruthScoring`; ``sharing`` (the segment-map
    traffic) by :class:`~scenarios.bench.sharing.SegmentPublisher` when the scenario shares.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> from scenarios.spec.layout import scenario_world
    >>> from robots.presets import get_preset
    >>> spec = load_scenario("pal1")
    >>> log = RunLog(spec=spec, world=scenario_world(spec), robot=get_preset(spec.robot),
    ...              segments=())
    >>> log.laps, log.sim_time_s
    ([], 0.0)
    """

    spec: ScenarioSpec
    world: WorldSpec
    robot: UGVSpec
    segments: tuple[PathSegment, ...]
    laps: list[LapLog] = field(default_factory=list)
    stamps: list[float] = field(default_factory=list)
    true_poses: list[np.ndarray] = field(default_factory=list)
    estimated_poses: list[np.ndarray] = field(default_factory=list)
    covariances: list[np.ndarray] = field(default_factory=list)
    ekf_history: dict[str, np.ndarray] = field(default_factory=dict)
    table1_distances: dict[str, list[float]] = field(default_factory=dict)
    reference_maps: dict[str, LocalMap] = field(default_factory=dict)
    maps_after_lap: list[dict] = field(default_factory=list)
    truth_after_lap: list[dict[str, np.ndarray]] = field(default_factory=list)
    example_pair: tuple[np.ndarray, np.ndarray] | None = None
    mapper_seconds: list[float] = field(default_factory=list)
    raycast_seconds: list[float] = field(default_factory=list)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    engine_time_s: float = 0.0
    sharing: dict | None = None
    vehicles: dict[str, RunLog] = field(default_factory=dict)
    safety_record: Any = None  # a scenarios.bench.safety_record.SafetyRecord


def combine_logs(fleet: RunLog, vehicles: dict[str, RunLog], store=None) -> None:
    """Fill a fleet's ``RunLog`` from its vehicles' logs: the fleet as a whole.

    Laps, poses, Table 1 distances (keys prefixed with the vehicle name), timings and
    EKF histories are the vehicles' together; the maps and ground truth after each lap
    are the first vehicle's. With a fleet map store (``semistatic.fleet``), ``sharing``
    holds the whole traffic and each vehicle's log the messages it sent.

    Examples
    --------
    >>> def log():  # only the parts combined here
    ...     return RunLog(spec=None, world=None, robot=None, segments=())
    >>> a, b, fleet = log(), log(), log()
    >>> a.laps.append(LapLog(lap=1, start_time=0.0))
    >>> b.laps.append(LapLog(lap=1, start_time=2.0))
    >>> b.table1_distances["east/0"] = [0.01]
    >>> combine_logs(fleet, {"a": a, "b": b})
    >>> [lap.start_time for lap in fleet.laps], fleet.table1_distances, list(fleet.vehicles)
    ([0.0, 2.0], {'b/east/0': [0.01]}, ['a', 'b'])
    """
    fleet.vehicles = dict(vehicles)
    logs = list(vehicles.values())
    for name, log in vehicles.items():
        fleet.laps += log.laps
        fleet.stamps += log.stamps
        fleet.true_poses += log.true_poses
        fleet.estimated_poses += log.estimated_poses
        fleet.covariances += log.covariances
        fleet.mapper_seconds += log.mapper_seconds
        fleet.raycast_seconds += log.raycast_seconds
        fleet.table1_distances.update(
            {f"{name}/{key}": value for key, value in log.table1_distances.items()})
        if fleet.example_pair is None:
            fleet.example_pair = log.example_pair
    histories = [log.ekf_history for log in logs if len(log.ekf_history.get("stamp", ()))]
    if histories:
        fleet.ekf_history = {key: np.concatenate([h[key] for h in histories])
                             for key in histories[0]}
    fleet.maps_after_lap = list(logs[0].maps_after_lap)
    fleet.truth_after_lap = list(logs[0].truth_after_lap)
    fleet.reference_maps = logs[0].reference_maps
    if store is not None:
        traffic = store.traffic_arrays()
        fleet.sharing = _traffic(store.totals(), traffic, np.ones(len(store.traffic), bool))
        for index, log in enumerate(logs):
            mine = traffic["sender"] == index if len(store.traffic) else np.zeros(0, bool)
            log.sharing = _traffic(None, traffic, mine)


def _traffic(totals: dict | None, traffic: dict, selected: np.ndarray) -> dict:
    if not selected.size:
        empty: list = []
        return {"messages": 0, "bytes": 0, "grid_bytes": 0, "stamp": empty,
                "message_bytes": empty, "message_grid_bytes": empty}
    sizes, grids = traffic["bytes"][selected], traffic["grid_bytes"][selected]
    if totals is None:
        totals = {"messages": int(selected.sum()), "bytes": int(sizes.sum()),
                  "grid_bytes": int(grids.sum())}
    return {**totals, "stamp": traffic["stamp"][selected].tolist(),
            "message_bytes": sizes.tolist(), "message_grid_bytes": grids.tolist()}
