"""Replaying a recording: the mapper, Table 1 and the scoring again, without physics.

A recording (:mod:`scenarios.logs.recording`) holds every safety scan with the poses the
mapper used and the ground truth around it. :func:`replay_recording` feeds those to fresh
local maps under other mapper thresholds and runs the scoring observers on a
:class:`ReplayedVehicle`, the recording's :class:`~scenarios.bench.observer.VehicleView`.
For mapper thresholds under the ``conservative`` policy the robot's motion cannot depend
on the thresholds, so a replay's Table 1 and detection figures equal a full
re-simulation's exactly.

Examples
--------
>>> ReplayedVehicle.fleet_size
1
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

import numpy as np

from robots.path import SplinePath
from scenarios.bench.observer import Observer
from scenarios.bench.records import LapLog, RunLog, ScanRecord
from scenarios.bench.scoring import GroundTruthScoring, Table1Reference
from scenarios.logs.recording import (
    IGNORED_FIELDS,
    MAPPER_SECTIONS,
    Recording,
    digest,
    spec_fingerprint,
)
from scenarios.results.metrics import table1_cm
from scenarios.results.outputs import detection_metrics
from scenarios.spec.layout import lap_worlds, robot_preset
from scenarios.spec.scenario import ScenarioSpec
from scenarios.spec.segments import PathSegment, path_segments
from semistatic.local_map import LocalMap
from semistatic.types import Scan
from worlds.spec import BoxSpec, WorldSpec

__all__ = ["ReplaySetting", "ReplayedVehicle", "replay_recording", "replay_setting"]


@dataclasses.dataclass(frozen=True)
class ReplaySetting:
    """What every replay of one recording under one scenario (but its mapper) shares."""

    worlds: tuple
    segments: tuple
    layouts: tuple[tuple[BoxSpec, ...], ...]
    laps: tuple[tuple[int, int, int, tuple[tuple, ...]], ...]
    """Per lap: its number, start and end layout, and its scans as tuples of the
    :class:`~scenarios.bench.records.ScanRecord` fields a replay does not compute, the lap's scan
    count, the layout and the people's positions."""


def replay_setting(recording: Recording, spec: ScenarioSpec) -> ReplaySetting:
    """Return the replay setting of ``recording`` under ``spec``, checked and cached.

    The mapper thresholds, which a replay changes, are not part of the cache key: the lap
    worlds, segments, scans and ground truth follow from the rest of the scenario, and so
    does its fingerprint but the mapper's digest. Raises :class:`SpecError` as
    :meth:`~scenarios.logs.recording.Recording.check_matches` does.
    """
    key = tuple(digest(getattr(spec, item.name)) for item in dataclasses.fields(spec)
                if item.name not in (*MAPPER_SECTIONS, *IGNORED_FIELDS))
    cached = recording.shared.get(key)
    if cached is None:
        worlds = lap_worlds(spec)
        fingerprint = spec_fingerprint(spec, worlds)
        recording.check_matches(spec, fingerprint)
        cached = recording.shared[key] = (fingerprint, _decoded(recording, worlds))
    else:
        fingerprint = {**cached[0], **{name: digest(getattr(spec, name))
                                       for name in MAPPER_SECTIONS}}
        recording.check_matches(spec, fingerprint)
    return cached[1]


def _decoded(recording: Recording, worlds: Sequence) -> ReplaySetting:
    """Return the replay setting of ``recording`` in its lap worlds ``worlds``."""
    base = worlds[0]
    arrays, manifest = recording.arrays, recording.manifest
    segment_names = manifest["segments"]
    offsets, people = arrays["people_offsets"], arrays["people"]
    header = arrays["header"].tolist()
    segment = arrays["segment"].tolist()
    lap_scans = arrays["lap_scans"].tolist()
    layout = arrays["layout"].tolist()
    laps = []
    for lap_layout in manifest["lap_layouts"]:
        lap = lap_layout["lap"]
        scans = []
        for index in np.flatnonzero(arrays["lap"] == lap).tolist():
            angle_min, increment, range_min, range_max, stamp = header[index]
            scan = Scan(ranges=arrays["ranges"][index], angle_min=angle_min,
                        angle_increment=increment, range_min=range_min, range_max=range_max,
                        stamp=stamp, pose=arrays["scan_pose"][index])
            persons = MappingProxyType(
                {str(k): people[k] for k in range(offsets[index], offsets[index + 1])})
            scans.append((scan, segment_names[segment[index]], arrays["sensor_pose"][index],
                          arrays["odom_pose"][index], arrays["ekf_pose"][index],
                          arrays["ekf_covariance"][index], lap_scans[index], layout[index],
                          persons))
        laps.append((lap, lap_layout["start"], lap_layout["end"], tuple(scans)))
    return ReplaySetting(
        worlds=worlds,
        segments=tuple(path_segments(base, SplinePath(base.path.knots))),
        layouts=tuple(
            tuple(BoxSpec(**{key: tuple(v) if isinstance(v, list) else v
                             for key, v in box.items()}) for box in boxes)
            for boxes in manifest["layouts"]
        ),
        laps=tuple(laps),
    )


class ReplayedVehicle:
    """A recording's :class:`~scenarios.bench.observer.VehicleView`: what its scans saw.

    The scoring observers read it as they read a running vehicle: the recorded box
    layouts, people, scans and lap counts, and the local maps the replay rebuilds. Poses
    are those the mapper used (the truth of a replay is the recorded layout).
    """

    fleet_size = 1

    def __init__(self, spec: ScenarioSpec, setting: ReplaySetting) -> None:
        self.spec = spec
        self.name = spec.name
        self.segments = tuple(setting.segments)
        self._segment_by_name = {segment.name: segment for segment in self.segments}
        self._local_maps = {
            seg.name: LocalMap(seg.origin, [seg.safety_area], params=spec.mapper, segment=seg.name)
            for seg in self.segments
        }
        self.local_maps = MappingProxyType(self._local_maps)
        self.log = RunLog(spec=spec, world=setting.worlds[0], robot=robot_preset(spec.robot),
                          segments=self.segments)
        self.robot = self.log.robot
        self._base_world = setting.worlds[0]
        self._layouts = setting.layouts
        self.layout_revision = -1
        self.world: WorldSpec = self._base_world
        self.lap_log: LapLog | None = None
        self.person_positions: Mapping[str, np.ndarray] = {}
        self.segment: PathSegment | None = None
        self.sim_time = 0.0
        self.time_step = 1.0 / spec.rates.physics_hz
        self.ekf_pose = self.ekf_covariance = self.true_pose = np.full(3, np.nan)
        self.true_twist = np.full(3, np.nan)
        self.zone, self.speed_scale = "free", 1.0

    @property
    def lap(self) -> int:
        """Return the lap being replayed."""
        return self.lap_log.lap

    def vehicle_outlines(self) -> list[np.ndarray]:
        """Return no outlines: a recording holds one vehicle."""
        return []

    def set_layout(self, index: int) -> None:
        """Put the recorded box layout ``index`` in force."""
        if index != self.layout_revision:
            self.layout_revision = int(index)
            self.world = dataclasses.replace(self._base_world, boxes=self._layouts[index])

    def set_scan(self, record: ScanRecord, lap_scans: int, persons: Mapping) -> None:
        """Show the state of the recorded scan ``record``."""
        self.segment = self._segment_by_name[record.segment]
        self.sim_time = record.scan.stamp
        self.ekf_pose, self.ekf_covariance = record.ekf_pose, record.ekf_covariance
        self.lap_log.safety_scans = lap_scans
        self.person_positions = persons


def replay_recording(recording: Recording, spec: ScenarioSpec) -> dict[str, Any]:
    """Re-run the mapper, Table 1 and the detection scoring of ``recording`` under ``spec``.

    Returns the recorded run's metrics with ``table1_cm`` and ``detection`` recomputed,
    ``performance.mapper_ms_median`` and ``wall_time_s`` measured anew (the recorded run's
    wall time moves to ``recorded_wall_time_s``), and ``performance.replay_stages_s``: the
    seconds spent in the mapper, the Table 1 experiment (``table1``), the ground-truth
    scoring (``scoring``) and the rest (``other``). ``spec`` must pass
    :meth:`~scenarios.logs.recording.Recording.check_matches`. The scans, poses and ground
    truth are decoded once per recording and shared by its replays (the mapper and the
    observers only read them).
    """
    started = time.perf_counter()
    setting = replay_setting(recording, spec)
    vehicle = ReplayedVehicle(spec, setting)
    observers: dict[str, Observer] = {"scoring": GroundTruthScoring(),
                                      "table1": Table1Reference()}
    stage_seconds = dict.fromkeys(("mapper", *observers), 0.0)

    def call(hook: str, *args) -> None:
        for stage, observer in observers.items():
            tick = time.perf_counter()
            getattr(observer, hook)(vehicle, *args)
            stage_seconds[stage] += time.perf_counter() - tick

    local_maps = vehicle.local_maps
    mapper_seconds = []
    for lap, start_layout, end_layout, scans in setting.laps:
        vehicle.set_layout(start_layout)
        vehicle.lap_log = lap_log = LapLog(lap=lap, start_time=0.0)
        call("on_lap_start", lap)
        for (scan, segment, sensor_pose, odom_pose, ekf_pose, ekf_covariance, lap_scans,
             layout, persons) in scans:
            vehicle.set_layout(layout)
            tick = time.perf_counter()
            report = local_maps[segment].update(scan, sensor_pose)
            mapper_seconds.append(time.perf_counter() - tick)
            record = ScanRecord(lap=lap, segment=segment, scan=scan, odom_pose=odom_pose,
                                ekf_pose=ekf_pose, ekf_covariance=ekf_covariance,
                                sensor_pose=sensor_pose, report=report)
            vehicle.set_scan(record, lap_scans, persons)
            call("on_scan", record)
        vehicle.set_layout(end_layout)
        call("on_lap_end", lap_log)
        vehicle.log.laps.append(lap_log)
    metrics = copy.deepcopy(recording.manifest["metrics"])
    metrics["table1_cm"] = table1_cm(vehicle.log.table1_distances)
    metrics["detection"] = detection_metrics(vehicle.log.laps)
    performance = metrics.setdefault("performance", {})
    performance["mapper_ms_median"] = (
        round(float(np.median(mapper_seconds)) * 1e3, 4) if mapper_seconds else None
    )
    # The sweep's wall time column is what this point cost: the replay, not the run.
    performance["recorded_wall_time_s"] = performance.get("wall_time_s")
    performance["wall_time_s"] = round(time.perf_counter() - started, 3)
    # Where the replay's time went: the mapper, the Table 1 experiment, the ground-truth
    # scoring, and the rest (checking the scenario, decoding the recording at its first
    # replay, the observers' calls, the metrics).
    stage_seconds["mapper"] = math.fsum(mapper_seconds)
    stage_seconds["other"] = performance["wall_time_s"] - math.fsum(stage_seconds.values())
    performance["replay_stages_s"] = {key: round(value, 3) for key, value in stage_seconds.items()}
    metrics["replayed_from"] = str(recording.path)
    return metrics
