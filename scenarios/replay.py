"""Replay the polyline mapper on a recorded laser log: the paper's experiment on real revisits.

A log has no path segments, so places stand in for them: the plane is cut into square
tiles, and every scan updates the local map of the tile its sensor is in (a
:class:`~semistatic.local_map.LocalMap` anchored at the tile corner, keeping every
polyline). The first pass through a tile builds its reference map; once the robot has
been away for ``revisit_gap`` seconds the map is frozen, and scans taken on later passes
are only associated with it, without merging, as the paper does with laps 2+ (Sec. 6).
Each reference polyline's restricted Hausdorff distances give Table 1 in the same schema
as ``semistatic run``.

Examples
--------
>>> import numpy as np
>>> from semistatic.types import Scan
>>> angles = np.radians(np.arange(-90.0, 90.5, 1.0))
>>> wall = 2.0 / np.cos(angles)  # a wall 2 m ahead, seen from the origin
>>> scan = Scan(ranges=np.where(np.abs(angles) < 1.2, wall, np.inf), angle_min=angles[0],
...             angle_increment=np.radians(1.0), range_max=20.0)
>>> result = replay([scan, scan], ReplayOptions(revisit_gap=0.0))
>>> result.scans, len(result.tiles)
(2, 1)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenarios.figures import plot_replay_map
from scenarios.metrics import table1_cm
from scenarios.outputs import csv_text, json_text, stage_and_publish, table1_rows
from semistatic.extraction import extract_polylines
from semistatic.local_map import LocalMap
from semistatic.logs import (
    QualitySummary,
    extraction_quality,
    inlier_mask,
    read_bag,
    read_carmen,
    summarize_quality,
)
from semistatic.logs.carmen import ReadStats
from semistatic.params import MapperParams
from semistatic.types import Scan

__all__ = [
    "REPLAY_PARAMS",
    "ReplayOptions",
    "ReplayResult",
    "open_log",
    "replay",
    "write_replay_outputs",
]

REPLAY_PARAMS = MapperParams(
    breakpoint_lambda=math.radians(10.0),
    breakpoint_sigma_r=0.03,
    min_points=3,
    max_range=8.0,
    hausdorff_restriction="projection",
)
"""Mapper thresholds for 1-degree, 80 m logs (CARMEN): wider breakpoint noise, 3-point
intervals, 8 m range (beyond it a 1-degree beam spacing exceeds 14 cm)."""


@dataclass(frozen=True)
class ReplayOptions:
    """How a log is replayed.

    ``every`` keeps one scan in N; ``tile_size`` (m) is the side of a place; a tile's
    reference is frozen once the robot was away from it for ``revisit_gap`` seconds.
    """

    params: MapperParams = REPLAY_PARAMS
    every: int = 1
    tile_size: float = 8.0
    revisit_gap: float = 20.0
    max_scans: int | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.every, int) and self.every >= 1):
            raise ValueError(f"ReplayOptions.every must be an integer >= 1, got {self.every!r}")
        if not self.tile_size > 0:
            raise ValueError(f"ReplayOptions.tile_size must be > 0 m, got {self.tile_size!r}")
        if not self.revisit_gap >= 0:
            raise ValueError(f"ReplayOptions.revisit_gap must be >= 0 s, got {self.revisit_gap!r}")


@dataclass
class _Tile:
    map: LocalMap
    last_stamp: float
    frozen: bool = False


@dataclass
class ReplayResult:
    """What a replay measured."""

    options: ReplayOptions
    scans: int = 0
    tiles: dict[tuple[int, int], _Tile] = field(default_factory=dict)
    table1_distances: dict[str, list[float]] = field(default_factory=dict)
    revisit_scans: int = 0
    quality: QualitySummary | None = None
    mapper_seconds: list[float] = field(default_factory=list)
    wall_time_s: float = 0.0
    trajectory: list[np.ndarray] = field(default_factory=list)
    raw_points: list[np.ndarray] = field(default_factory=list)

    def summary(self) -> dict:
        """Return the ``metrics.json`` content (the ``table1_cm`` schema of ``run``)."""
        quality = self.quality
        polylines = sum(len(tile.map) for tile in self.tiles.values())
        return {
            "scans": self.scans,
            "tiles": len(self.tiles),
            "revisit_scans": self.revisit_scans,
            "map_polylines": polylines,
            "table1_cm": table1_cm(self.table1_distances),
            "extraction": None if quality is None else {
                "coverage": round(quality.coverage, 6),
                "in_span_fraction": round(quality.in_span_fraction, 6),
                "rms_distance_m": round(quality.rms_distance, 6),
                "max_distance_m": round(quality.max_distance, 6),
                "vertices_per_scan": round(quality.vertices_per_scan, 3),
                "polylines_per_scan": round(quality.polylines_per_scan, 3),
            },
            "params": {
                "every": self.options.every,
                "tile_size_m": self.options.tile_size,
                "revisit_gap_s": self.options.revisit_gap,
                "max_range_m": self.options.params.max_range,
                "epsilon_m": self.options.params.epsilon,
                "gate_m": self.options.params.gate,
                "hausdorff_restriction": self.options.params.hausdorff_restriction,
            },
            "performance": {
                "wall_time_s": round(self.wall_time_s, 3),
                "mapper_ms_median": round(float(np.median(self.mapper_seconds)) * 1e3, 4)
                if self.mapper_seconds else None,
                "scans_per_s": (
                    round(self.scans / self.wall_time_s, 1) if self.wall_time_s else None
                ),
            },
        }


def open_log(path: str | Path, *, lenient: bool = False,
             stats: ReadStats | None = None) -> Iterator[Scan]:
    """Return the scans of a CARMEN log (``.log``/``.gz``) or a ROS 1/2 bag, streamed."""
    path = Path(path)
    if path.is_dir() or path.suffix in (".bag", ".db3", ".mcap"):
        return read_bag(path)
    return read_carmen(path, lenient=lenient, stats=stats)


def _tile_key(position: np.ndarray, size: float) -> tuple[int, int]:
    return (math.floor(position[0] / size), math.floor(position[1] / size))


def replay(
    scans: Iterable[Scan],
    options: ReplayOptions | None = None,
    *,
    progress: Callable[[int], None] | None = None,
) -> ReplayResult:
    """Run extraction, association, merge and join over ``scans`` into per-place maps."""
    options = ReplayOptions() if options is None else options
    params = options.params
    result = ReplayResult(options)
    qualities = []
    started = time.perf_counter()
    for index, scan in enumerate(scans):
        if options.max_scans is not None and result.scans >= options.max_scans:
            break
        if index % options.every:
            continue
        result.scans += 1
        pose = scan.pose
        key = _tile_key(pose[:2], options.tile_size)
        # A tile left for long enough is a place visited before: freeze its reference.
        for other_key, other in result.tiles.items():
            if other_key != key and not other.frozen and len(other.map):
                other.frozen = scan.stamp - other.last_stamp >= options.revisit_gap
        tile = result.tiles.get(key)
        if tile is None:
            origin = (key[0] * options.tile_size, key[1] * options.tile_size, 0.0)
            tile = result.tiles[key] = _Tile(LocalMap(origin, None, segment=f"{key[0]},{key[1]}",
                                                      params=params), scan.stamp)
        clock = time.perf_counter()
        report = tile.map.update(scan, pose, merge=not tile.frozen)
        result.mapper_seconds.append(time.perf_counter() - clock)
        if tile.frozen:
            result.revisit_scans += 1
            for pair in report.associated:
                name = f"{tile.map.segment}/{pair.map_id}"
                result.table1_distances.setdefault(name, []).append(pair.distance)
        else:
            tile.last_stamp = scan.stamp
        polylines = extract_polylines(scan, params)
        qualities.append(extraction_quality(
            scan, polylines, params.epsilon, max_range=params.max_range,
            inliers=inlier_mask(scan, params),
        ))
        result.trajectory.append(np.asarray(pose, dtype=float))
        if result.scans % 10 == 1:
            valid = scan.valid_mask() & (scan.ranges <= params.max_range)
            result.raw_points.append(scan.world_points()[valid])
        if progress is not None:
            progress(1)
    result.quality = summarize_quality(qualities) if qualities else None
    result.wall_time_s = time.perf_counter() - started
    return result


def write_replay_outputs(result: ReplayResult, out: str | Path, *, log_name: str,
                         figures: bool = True) -> dict:
    """Write ``metrics.json``, ``table1.csv``, ``map.geojson`` and the figure; return metrics.

    Files are staged beside ``out`` and moved in only when all exist (nothing half-written).
    """
    metrics = {"log": log_name, **result.summary()}
    collections = {"/".join(map(str, key)): tile.map.to_geojson()
                   for key, tile in sorted(result.tiles.items())}
    features = [f for collection in collections.values() for f in collection["features"]]

    def fill(staging: Path) -> None:
        (staging / "metrics.json").write_text(json_text(metrics))
        (staging / "table1.csv").write_text(
            csv_text(table1_rows(log_name, metrics["table1_cm"]))
        )
        (staging / "map.geojson").write_text(
            json_text({"type": "FeatureCollection", "features": features})
        )
        if figures:
            lines = [line.points for tile in result.tiles.values()
                     for line in tile.map.world_polylines().values()]
            raw = np.vstack(result.raw_points) if result.raw_points else np.empty((0, 2))
            plot_replay_map(lines, raw, np.asarray(result.trajectory),
                            staging / "figures" / "replay_map.png",
                            title=f"{log_name}: polyline map over the raw laser points")

    stage_and_publish(Path(out), fill)
    return metrics

