"""Replay the polyline mapper on a recorded laser log: the paper's experiment on real revisits.

A log has no path segments, so places stand in for them: the plane is cut into square
tiles, and every scan updates the local map of the tile its sensor is in (a
:class:`~semistatic.local_map.LocalMap` anchored at the tile corner, keeping every
polyline). The first pass through a tile builds its reference map; once the robot has
been away for ``revisit_gap`` seconds the map is frozen, and scans taken on later passes
are only associated with it, without merging, as the paper does with laps 2+ (Sec. 6).
Each reference polyline's restricted Hausdorff distances give Table 1 in the same schema
as ``semistatic run``.

The paper's robot is localised on reflectors to about 1 cm; a log's poses come from
elsewhere (SLAM), and on the Intel and ACES logs a revisit scan sits a median 2.8 cm away
from where the first pass saw the same walls. With ``align`` (the default) each revisit
scan is first aligned to the reference map of its tile
(:func:`semistatic.alignment.align_points`: point-to-line ICP, bounded, corrected only in
the directions the geometry constrains, e.g. across a corridor but not along it), as a robot
localised on its map would see the place; the
distances at the logged poses are kept beside (``alignment.table1_cm_log_pose``), with
the correction statistics, in ``metrics.json``. Aligning does not shrink the figure by
itself: on a log whose poses are right it leaves Table 1 unchanged
(``tests/scenarios/test_replay.py``).

Logs differ in range noise (ACES about 3.5 times Intel's, 1.7 vs 0.5 cm across surfaces):
:func:`semistatic.noise.estimate_range_noise` measures it on the first ``noise_scans`` scans
and ``metrics.json`` reports it. With ``auto_noise`` (the default) the Douglas-Peucker
tolerance is three times that noise and the breakpoint noise at least the noise
(:func:`semistatic.noise.noise_params`), so that polylines simplify the shape, not the noise.

Examples
--------
>>> import numpy as np
>>> from semistatic.types import Scan
>>> angles = np.radians(np.arange(-90.0, 90.5, 1.0))
>>> wall = 2.0 / np.cos(angles)  # a wall 2 m ahead, seen from the origin
>>> scan = Scan(ranges=np.where(np.abs(angles) < 1.2, wall, np.inf), angle_min=angles[0],
...             angle_increment=np.radians(1.0), range_max=20.0)
>>> result = replay_log([scan, scan], ReplayOptions(revisit_gap=0.0))
>>> result.scans, len(result.tiles)
(2, 1)
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenarios.results.figures import plot_replay_map
from scenarios.results.metrics import table1_cm
from scenarios.results.outputs import csv_text, json_text, stage_and_publish, table1_rows
from semistatic.alignment import Alignment, AlignmentParams, align_points, polyline_segments
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
from semistatic.noise import NOISE_EPSILON_SIGMAS, estimate_range_noise, noise_params
from semistatic.params import MapperParams
from semistatic.types import Scan

__all__ = [
    "NOISE_EPSILON_SIGMAS",
    "NOISE_SCANS",
    "REPLAY_ALIGNMENT",
    "REPLAY_PARAMS",
    "ReplayOptions",
    "ReplayResult",
    "estimate_range_noise",
    "noise_params",
    "open_log",
    "replay_log",
    "write_replay_outputs",
]

NOISE_SCANS = 50
"""Scans at the start of a log on which its range noise is measured (on the Intel and ACES
logs the first 50 give 0.47 and 1.67 cm, all scans 0.50 and 1.75 cm)."""


def _rounded(value: float, digits: int) -> float | None:
    """Return ``value`` rounded, or None when it is not finite (JSON has no NaN)."""
    return round(value, digits) if math.isfinite(value) else None


REPLAY_PARAMS = MapperParams(
    breakpoint_lambda=math.radians(12.0),
    breakpoint_sigma_r=0.03,
    max_range=8.0,
    hausdorff_restriction="projection",
    free_space_cut=False,
)
"""Mapper thresholds for 1-degree, 80 m logs (CARMEN): wider breakpoint noise, 8 m range
(beyond it a 1-degree beam spacing exceeds 14 cm). The Douglas-Peucker tolerance follows
the log's measured range noise (``ReplayOptions.auto_noise``, the default).

The breakpoint angle is 12 deg: at one-degree beams a surface seen beyond 78 deg incidence
is split where its readings step apart. Those grazing readings are the noisiest along
their rays (range noise over the cosine of the incidence), and an edge through them tilts
the polylines that revisits are compared with. Measured on the real logs (revisit Table 1
mean of means, intel / aces): 10 deg 4.49 / 4.69 cm, 12 deg 4.41 / 4.49 cm, 15 deg
4.43 / 4.54 cm; every per-polyline mean under 10 cm only at 12 deg.

No free-space cut (``MapperParams.free_space_cut``): a place's reference is built in one
pass, in which nothing semi-static moves; what its scans read through there is pose error
between them (GMapping's, a few centimetres), people and doors, and cutting the reference
on that only reshuffles which polylines revisits are compared with (measured: intel
4.35 -> 4.38 cm, aces 4.40 -> 4.60 cm with the cut)."""


REPLAY_ALIGNMENT = AlignmentParams(min_points=10)
"""Scan-to-reference alignment of revisit scans (when ``ReplayOptions.align``): a 20 cm
correspondence gate, 2 cm Cauchy scale (about the logs' range noise), corrections bounded to
30 cm and 5 deg, rejected on fewer than 10 matched points; directions the geometry leaves
open are kept as logged (partial alignment). Ten points, not the default 30: a revisit of a
place seen through a doorway or along a short wall matches a few metres of it, and the
constraint test, not the point count, decides what such a match can correct. Measured
(Table 1 mean of means, intel / aces): 30 points 4.31 / 4.33 cm (168 intel revisit scans
left unaligned for too few points), 20: 4.29 / 4.32, 10: 4.27 / 4.32."""


@dataclass(frozen=True)
class ReplayOptions:
    """How a log is replayed.

    ``every`` keeps one scan in N; ``tile_size`` (m) is the side of a place; a tile's
    reference is frozen once the robot was away from it for ``revisit_gap`` seconds.
    ``align`` aligns each revisit scan to its tile's reference before association
    (thresholds ``alignment``); the module docstring says why. The range noise is
    measured on the first ``noise_scans`` scans of the log; ``auto_noise`` fits
    ``params`` to it with :func:`noise_params`.
    """

    params: MapperParams = REPLAY_PARAMS
    every: int = 1
    tile_size: float = 8.0
    revisit_gap: float = 20.0
    max_scans: int | None = None
    align: bool = True
    alignment: AlignmentParams = REPLAY_ALIGNMENT
    auto_noise: bool = True
    noise_scans: int = NOISE_SCANS

    def __post_init__(self) -> None:
        if not (isinstance(self.every, int) and self.every >= 1):
            raise ValueError(f"ReplayOptions.every must be an integer >= 1, got {self.every!r}")
        if not self.tile_size > 0:
            raise ValueError(f"ReplayOptions.tile_size must be > 0 m, got {self.tile_size!r}")
        if not self.revisit_gap >= 0:
            raise ValueError(f"ReplayOptions.revisit_gap must be >= 0 s, got {self.revisit_gap!r}")
        if not isinstance(self.align, bool):
            raise ValueError(f"ReplayOptions.align must be True or False, got {self.align!r}")
        if not isinstance(self.alignment, AlignmentParams):
            raise ValueError(
                f"ReplayOptions.alignment must be an AlignmentParams, got {self.alignment!r}"
            )
        if not isinstance(self.auto_noise, bool):
            raise ValueError(
                f"ReplayOptions.auto_noise must be True or False, got {self.auto_noise!r}"
            )
        if not (isinstance(self.noise_scans, int) and self.noise_scans >= 1):
            raise ValueError(
                f"ReplayOptions.noise_scans must be an integer >= 1 (scans to measure the "
                f"range noise on), got {self.noise_scans!r}"
            )


@dataclass
class _Tile:
    map: LocalMap
    last_stamp: float
    frozen: bool = False
    segments: tuple[np.ndarray, np.ndarray] | None = None

    def reference_segments(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the frozen reference map's segments in the world frame (computed once)."""
        if self.segments is None:
            self.segments = polyline_segments(
                line.points for line in self.map.world_polylines().values()
            )
        return self.segments


@dataclass
class ReplayResult:
    """What a replay measured.

    ``table1_distances`` are the restricted Hausdorff distances (m) of each reference
    polyline on revisits (at the aligned poses when ``options.align``);
    ``log_pose_distances`` the same at the logged poses (filled only when aligning);
    ``alignments`` one :class:`~semistatic.alignment.Alignment` per revisit scan;
    ``noise_sigma`` the range noise measured on the first scans (m, ``nan`` if there was
    nothing to measure) and ``params`` the thresholds used (``options.params``, fitted to
    the noise when ``options.auto_noise``).
    """

    options: ReplayOptions
    params: MapperParams | None = None
    noise_sigma: float = math.nan
    scans: int = 0
    tiles: dict[tuple[int, int], _Tile] = field(default_factory=dict)
    table1_distances: dict[str, list[float]] = field(default_factory=dict)
    log_pose_distances: dict[str, list[float]] = field(default_factory=dict)
    revisit_scans: int = 0
    quality: QualitySummary | None = None
    mapper_seconds: list[float] = field(default_factory=list)
    wall_time_s: float = 0.0
    trajectory: list[np.ndarray] = field(default_factory=list)
    raw_points: list[np.ndarray] = field(default_factory=list)
    alignments: list[Alignment] = field(default_factory=list)
    alignment_seconds: list[float] = field(default_factory=list)

    def summary(self) -> dict:
        """Return the ``metrics.json`` content (the ``table1_cm`` schema of ``run``)."""
        quality = self.quality
        params = self.options.params if self.params is None else self.params
        polylines = sum(len(tile.map) for tile in self.tiles.values())
        return {
            "scans": self.scans,
            "tiles": len(self.tiles),
            "revisit_scans": self.revisit_scans,
            "map_polylines": polylines,
            "table1_cm": table1_cm(self.table1_distances),
            "extraction": None if quality is None else {
                # None (JSON null) where no scan had a valid reading to measure.
                "coverage": _rounded(quality.coverage, 6),
                "in_span_fraction": _rounded(quality.in_span_fraction, 6),
                "rms_distance_m": _rounded(quality.rms_distance, 6),
                "max_distance_m": _rounded(quality.max_distance, 6),
                "vertices_per_scan": round(quality.vertices_per_scan, 3),
                "polylines_per_scan": round(quality.polylines_per_scan, 3),
            },
            "params": {
                "every": self.options.every,
                "tile_size_m": self.options.tile_size,
                "revisit_gap_s": self.options.revisit_gap,
                "max_range_m": params.max_range,
                "epsilon_m": round(params.epsilon, 6),
                "breakpoint_sigma_r_m": round(params.breakpoint_sigma_r, 6),
                "gate_m": params.gate,
                "hausdorff_restriction": params.hausdorff_restriction,
                "align": self.options.align,
                "auto_noise": self.options.auto_noise,
            },
            "noise": {
                "sigma_cm": (
                    None if math.isnan(self.noise_sigma) else round(self.noise_sigma * 100.0, 4)
                ),
                "scans": self.options.noise_scans,
                "rule": (
                    f"epsilon >= {NOISE_EPSILON_SIGMAS:g} sigma, breakpoint_sigma_r >= sigma"
                    if self.options.auto_noise else None
                ),
            },
            "alignment": (
                _alignment_summary(self.alignments, self.log_pose_distances)
                if self.options.align else None
            ),
            "performance": {
                "wall_time_s": round(self.wall_time_s, 3),
                "mapper_ms_median": round(float(np.median(self.mapper_seconds)) * 1e3, 4)
                if self.mapper_seconds else None,
                "alignment_ms_median": (
                    round(float(np.median(self.alignment_seconds)) * 1e3, 4)
                    if self.alignment_seconds else None
                ),
                "scans_per_s": (
                    round(self.scans / self.wall_time_s, 1) if self.wall_time_s else None
                ),
            },
        }


def _alignment_summary(alignments: list[Alignment], log_pose_distances: dict) -> dict:
    """Return how many revisit scans were aligned, how far, and Table 1 at the logged poses."""
    accepted = [a for a in alignments if a.accepted]
    reasons: dict[str, int] = {}
    for alignment in alignments:
        if not alignment.accepted:
            reasons[alignment.reason] = reasons.get(alignment.reason, 0) + 1

    def spread(values: list[float], scale: float) -> dict:
        if not values:
            return {"median": None, "p90": None, "max": None}
        values = np.asarray(values) * scale
        return {"median": round(float(np.median(values)), 4),
                "p90": round(float(np.percentile(values, 90)), 4),
                "max": round(float(values.max()), 4)}

    return {
        "attempted": len(alignments),
        "accepted": len(accepted),
        # Accepted with a direction the geometry leaves open kept as logged (a corridor).
        "partial": sum(a.partial for a in accepted),
        "rejected": dict(sorted(reasons.items())),
        "translation_cm": spread([a.translation for a in accepted], 100.0),
        "rotation_deg": spread([a.rotation for a in accepted], 180.0 / math.pi),
        "rms_before_cm": spread([a.rms_before for a in accepted], 100.0),
        "rms_after_cm": spread([a.rms_after for a in accepted], 100.0),
        "table1_cm_log_pose": table1_cm(log_pose_distances),
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


def replay_log(
    scans: Iterable[Scan],
    options: ReplayOptions | None = None,
    *,
    progress: Callable[[int], None] | None = None,
    on_scan: Callable[[Scan, np.ndarray, LocalMap], None] | None = None,
) -> ReplayResult:
    """Run extraction, association, merge and join over ``scans`` into per-place maps.

    ``on_scan``, when given, is called after each replayed scan with the scan, the laser
    pose the mapper used (aligned on a revisit) and the place's map (e.g.
    :meth:`scenarios.logs.rrd.RerunRecorder.replayed_scan`).
    """
    options = ReplayOptions() if options is None else options
    started = time.perf_counter()
    scans = iter(scans)
    first = list(itertools.islice(scans, options.noise_scans))
    sigma = estimate_range_noise(first, options.params.max_range)
    params = noise_params(options.params, sigma) if options.auto_noise else options.params
    result = ReplayResult(options, params=params, noise_sigma=sigma)
    qualities = []
    for index, scan in enumerate(itertools.chain(first, scans)):
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
        inliers = inlier_mask(scan, params)
        if tile.frozen and options.align:
            # The same association at the logged pose: the figure without alignment.
            for pair in tile.map.associate(scan, pose, find_missed=False).associated:
                name = f"{tile.map.segment}/{pair.map_id}"
                result.log_pose_distances.setdefault(name, []).append(pair.distance)
            clock = time.perf_counter()
            alignment = align_points(scan.points()[inliers], *tile.reference_segments(), pose,
                                     options.alignment)
            result.alignment_seconds.append(time.perf_counter() - clock)
            result.alignments.append(alignment)
            pose = alignment.pose
        clock = time.perf_counter()
        # Revisits are only associated (Table 1 reads the pairs, not the missed polylines).
        report = (tile.map.associate(scan, pose, find_missed=False) if tile.frozen
                  else tile.map.update(scan, pose))
        result.mapper_seconds.append(time.perf_counter() - clock)
        if on_scan is not None:
            on_scan(scan, pose, tile.map)
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
            inliers=inliers,
        ))
        result.trajectory.append(np.asarray(scan.pose, dtype=float))
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

    stage_and_publish(Path(out), fill, command="replay")
    return metrics

