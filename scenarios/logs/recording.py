"""Recordings: what the mapper and the scoring saw in a run, to replay without physics.

``semistatic run SCENARIO --record DIR`` attaches a :class:`ScanRecorder` and writes::

    DIR/manifest.json   format and project version, the scenario's fingerprint (a digest
                        of every scenario field but the mapper thresholds), the segments,
                        every box layout the run had (name, size, pose), and the run's
                        metrics.json content
    DIR/scans.npz       one row per safety scan (numpy's open NPZ, read without pickle):
                        ranges and scan header, the true sensor pose, the EKF robot pose,
                        covariance and sensor pose the mapper used, odometry, lap, segment,
                        the lap's scan count, the box layout in force, people positions

Everything is float64 as the run had it, so a replay
(:func:`scenarios.logs.recording_replay.replay_recording`) feeds the mapper bit-identical
scans and poses, and the ground-truth scoring and the paper's Table 1 experiment
(:class:`~scenarios.bench.scoring.GroundTruthScoring`,
:class:`~scenarios.bench.scoring.Table1Reference`) see what they saw in the run. For mapper
thresholds under the ``conservative`` policy, whose fields ignore the maps, the robot's
motion cannot depend on the thresholds, and a replay's Table 1 and detection figures equal
a full re-simulation's exactly.

Examples
--------
>>> from scenarios.spec.load import load_scenario
>>> motion_changes(load_scenario("pal1"), load_scenario("pal1", overrides=["mapper.gate=0.2"]))
()
>>> motion_changes(load_scenario("pal1"), load_scenario("pal1", overrides=["noise.range=2"]))
('noise',)
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.metadata
import json
import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from scenarios.bench.observer import Observer, VehicleView
from scenarios.bench.policies import policy_name
from scenarios.bench.records import LapLog, ScanRecord
from scenarios.logs.recording_checks import (
    MANIFEST,
    RECORDING_OPTION,
    SCANS,
    check_manifest,
    file_digest,
    read_scans,
)
from scenarios.process.staging import check_writable_parent
from scenarios.spec.layout import lap_worlds
from scenarios.spec.scenario import LOADER_FIELDS, ScenarioSpec
from semistatic.errors import SpecError
from semistatic.inputs import MAX_JSON_BYTES, read_bounded
from semistatic.validation import loads_json

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "MAPPER_SECTIONS",
    "Recording",
    "ScanRecorder",
    "check_new_recording_path",
    "digest",
    "motion_changes",
    "read_recording",
    "spec_fingerprint",
]

FORMAT = "semistatic-recording"
FORMAT_VERSION = 2
"""Raised whenever the layout of ``manifest.json`` or ``scans.npz`` changes incompatibly
(2: the manifest holds the scan and beam counts and the sha256 of ``scans.npz``)."""

MAPPER_SECTIONS = ("mapper",)
"""Scenario fields a replay may change: they reach only the mapper, never the motion."""

IGNORED_FIELDS = LOADER_FIELDS
"""Scenario fields that say where a spec came from, not what it runs."""



def digest(value: Any) -> str:
    """Return a short digest of a spec value (frozen dataclasses: ``repr`` is canonical).

    Examples
    --------
    >>> digest((1.0, "a")) == digest((1.0, "a")) != digest((1.0, "b"))
    True
    """
    return hashlib.sha256(repr(value).encode()).hexdigest()[:16]


def spec_fingerprint(spec: ScenarioSpec, worlds: Sequence | None = None) -> dict[str, str]:
    """Return a digest of every scenario field (but its source), by field name.

    The world is digested as the lap layouts built from it (``worlds``, built when not
    given), so editing the world file changes the fingerprint.

    Examples
    --------
    >>> from scenarios.spec.load import load_scenario
    >>> a = spec_fingerprint(load_scenario("pal1"))
    >>> b = spec_fingerprint(load_scenario("pal1", overrides=["mapper.gate=0.3"]))
    >>> [key for key in a if a[key] != b[key]]
    ['mapper']
    """
    fingerprint = {
        item.name: digest(getattr(spec, item.name))
        for item in dataclasses.fields(spec)
        if item.name not in IGNORED_FIELDS
    }
    fingerprint["world_spec"] = digest(lap_worlds(spec) if worlds is None else worlds)
    return fingerprint


def _motion_fields(recorded: Mapping[str, str], policy: str,
                   wanted: Mapping[str, str]) -> tuple[str, ...]:
    # Under a policy other than conservative the fields follow the maps: then the
    # mapper thresholds change the motion as well.
    replayable = MAPPER_SECTIONS if policy == "conservative" else ()
    return tuple(
        key for key in wanted if recorded.get(key) != wanted[key] and key not in replayable
    )


def motion_changes(recorded: ScenarioSpec, wanted: ScenarioSpec) -> tuple[str, ...]:
    """Return the scenario fields of ``wanted`` that a replay of ``recorded`` cannot honour.

    Those are the fields that differ, except the mapper thresholds under the
    ``conservative`` policy (whose fields ignore the maps, so the motion cannot change).
    """
    return _motion_fields(spec_fingerprint(recorded), policy_name(recorded.policy),
                          spec_fingerprint(wanted))


def _project_version() -> str:
    return importlib.metadata.version("semistatic")


class ScanRecorder(Observer):
    """Observer collecting each safety scan's mapper inputs and each lap's ground truth.

    Attach it to a :class:`~scenarios.bench.testbench.Testbench`, run, then :meth:`write` with
    the run's metrics.

    Examples
    --------
    >>> ScanRecorder().scans
    0
    """

    def __init__(self) -> None:
        self._rows: dict[str, list] = {name: [] for name in (
            "ranges", "header", "scan_pose", "sensor_pose", "ekf_pose", "ekf_covariance",
            "odom_pose", "lap", "segment", "lap_scans", "layout",
        )}
        self._people: list[np.ndarray] = []
        self._people_counts: list[int] = []
        self._layouts: list[list[dict]] = []
        self._layout_of_revision: dict[int, int] = {}
        self._lap_layouts: list[dict[str, int]] = []
        self._segments: list[str] = []

    @property
    def scans(self) -> int:
        """Return how many scans were recorded."""
        return len(self._rows["lap"])

    def _layout(self, vehicle: VehicleView) -> int:
        revision = vehicle.layout_revision
        if revision not in self._layout_of_revision:
            self._layout_of_revision[revision] = len(self._layouts)
            self._layouts.append([dataclasses.asdict(box) for box in vehicle.world.boxes])
        return self._layout_of_revision[revision]

    def on_lap_start(self, vehicle: VehicleView, lap: int) -> None:
        """Note the segments and the lap's box layout."""
        self._segments = [segment.name for segment in vehicle.segments]
        self._lap_layouts.append({"lap": lap, "start": self._layout(vehicle)})

    def on_scan(self, vehicle: VehicleView, record: ScanRecord) -> None:
        """Keep the scan, the poses the mapper used, and the ground truth around it."""
        scan, rows = record.scan, self._rows
        rows["ranges"].append(scan.ranges)
        rows["header"].append((scan.angle_min, scan.angle_increment, scan.range_min,
                               scan.range_max, scan.stamp))
        rows["scan_pose"].append(scan.pose)
        rows["sensor_pose"].append(record.sensor_pose)
        rows["ekf_pose"].append(record.ekf_pose)
        rows["ekf_covariance"].append(record.ekf_covariance)
        rows["odom_pose"].append(record.odom_pose)
        rows["lap"].append(record.lap)
        rows["segment"].append(self._segments.index(record.segment))
        rows["lap_scans"].append(vehicle.lap_log.safety_scans)
        rows["layout"].append(self._layout(vehicle))
        people = [p for p in vehicle.person_positions.values() if p is not None]
        self._people.extend(np.asarray(p, dtype=np.float64).reshape(2) for p in people)
        self._people_counts.append(len(people))

    def on_lap_end(self, vehicle: VehicleView, lap_log: LapLog) -> None:
        """Note the layout the lap was scored against."""
        self._lap_layouts[-1]["end"] = self._layout(vehicle)

    def write(self, directory: str | os.PathLike[str], spec: ScenarioSpec,
              metrics: Mapping[str, Any], worlds: Sequence | None = None) -> None:
        """Write the recording as the new directory ``directory``.

        The files go into a staging directory beside it, renamed into place when complete,
        so an interruption never leaves a recording that looks whole. ``worlds``, the
        run's lap worlds (:func:`scenarios.spec.layout.lap_worlds`), fingerprint the
        world the run drove; without them the world file is read again.
        """
        directory = Path(directory)
        arrays = {
            "ranges": np.asarray(self._rows["ranges"], dtype=np.float64),
            "header": np.asarray(self._rows["header"], dtype=np.float64),
            **{
                name: np.asarray(self._rows[name], dtype=np.float64)
                for name in ("scan_pose", "sensor_pose", "ekf_pose", "ekf_covariance",
                             "odom_pose")
            },
            **{name: np.asarray(self._rows[name], dtype=np.int64)
               for name in ("lap", "segment", "lap_scans", "layout")},
            "people": np.asarray(self._people, dtype=np.float64).reshape(-1, 2),
            "people_offsets": np.concatenate([[0], np.cumsum(self._people_counts)]).astype(
                np.int64
            ),
        }
        manifest = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "project_version": _project_version(),
            "scenario": spec.name,
            "seed": spec.seed,
            "laps": spec.laps,
            "policy": policy_name(spec.policy),
            "scenario_source": spec.source,
            "fingerprint": spec_fingerprint(spec, worlds),
            "segments": self._segments,
            "layouts": self._layouts,
            "lap_layouts": self._lap_layouts,
            "metrics": metrics,
            "scans": int(arrays["ranges"].shape[0]),
            "beams": int(arrays["ranges"].shape[1]) if arrays["ranges"].ndim == 2 else 0,
        }
        directory.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{directory.name}.staging-",
                                        dir=directory.parent))
        try:
            np.savez(staging / SCANS, **arrays)
            # The reader checks it: a scans.npz edited or swapped afterwards is refused.
            manifest["scans_sha256"] = file_digest(staging / SCANS)
            (staging / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
            os.rename(staging, directory)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise


def check_new_recording_path(path: str | os.PathLike[str]) -> Path:
    """Return ``path`` if a recording can be created there, else raise :class:`SpecError`.

    Called before the run, so that a bad ``--record`` costs nothing.

    Examples
    --------
    >>> import tempfile
    >>> folder = tempfile.mkdtemp()
    >>> check_new_recording_path(folder)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --record: ...: exists already; choose a new directory name
    >>> check_new_recording_path(Path(folder) / "rec").name
    'rec'
    """
    path = Path(path)
    if path.exists():
        raise SpecError("--record", str(path), "exists already; choose a new directory name")
    check_writable_parent(path, option="--record")
    return path


@dataclasses.dataclass(frozen=True, eq=False)
class Recording:
    """A recording read back: its manifest and its per-scan arrays.

    Examples
    --------
    >>> Recording(Path("rec"), {"scenario": "pal1"}, {}).manifest["scenario"]
    'pal1'
    """

    path: Path
    manifest: dict[str, Any]
    arrays: dict[str, np.ndarray]
    shared: dict[Any, Any] = dataclasses.field(default_factory=dict, init=False, repr=False)
    """What every replay of this recording shares, built at the first
    (:mod:`scenarios.logs.recording_replay`): many threshold points rebuild none of it."""

    def check_matches(self, spec: ScenarioSpec,
                      fingerprint: Mapping[str, str] | None = None) -> None:
        """Raise :class:`SpecError` unless ``spec`` may be replayed from this recording.

        ``spec`` must be the recorded scenario (same fingerprint, computed when not
        given), differing at most in the mapper thresholds, and those only under the
        conservative policy.
        """
        fingerprint = spec_fingerprint(spec) if fingerprint is None else fingerprint
        manifest = self.manifest
        if manifest["scenario"] != spec.name:
            raise SpecError(
                RECORDING_OPTION, "scenario",
                f"{self.path} records scenario {manifest['scenario']!r}, not {spec.name!r}; "
                f"record {spec.name} with `semistatic run {spec.name} --record DIR`",
            )
        changed = _motion_fields(manifest["fingerprint"], manifest["policy"], fingerprint)
        if changed:
            raise SpecError(
                RECORDING_OPTION, ", ".join(changed),
                f"differs from the recording {self.path} (seed {manifest['seed']}, "
                f"{manifest['laps']} laps, policy {manifest['policy']}) and changes the "
                "robot's motion: a recording replays only mapper thresholds under the "
                "conservative policy; drop --recording to re-simulate",
            )


def read_recording(path: str | os.PathLike[str]) -> Recording:
    """Read a recording written by :meth:`ScanRecorder.write`; refuse others.

    Raises :class:`SpecError` (``error: --recording: ...``) for a missing or foreign
    directory and for another format version.

    Examples
    --------
    >>> read_recording("/nonexistent")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --recording: manifest.json: /nonexistent is not a recording \
(no manifest.json); make one with `semistatic run SCENARIO --record DIR`
    """
    path = Path(path)
    if not (path / MANIFEST).exists():
        raise SpecError(
            RECORDING_OPTION, MANIFEST,
            f"{path} is not a recording (no {MANIFEST}); make one with "
            "`semistatic run SCENARIO --record DIR`",
        )
    raw = read_bounded(path / MANIFEST, limit=MAX_JSON_BYTES, what="recording manifest",
                       file=RECORDING_OPTION, key=MANIFEST)
    try:
        manifest = loads_json(raw.decode("utf-8"), file=RECORDING_OPTION, key=MANIFEST)
    except SpecError:
        raise  # nested too deep: already one line naming --recording (a ValueError too)
    except ValueError as error:  # not UTF-8, not JSON
        raise SpecError(RECORDING_OPTION, MANIFEST, f"cannot read {path / MANIFEST}: {error}") \
            from None
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise SpecError(RECORDING_OPTION, "format", f"{path} is not a {FORMAT}")
    if manifest.get("format_version") != FORMAT_VERSION:
        raise SpecError(
            RECORDING_OPTION, "format_version",
            f"{path} has format version {manifest.get('format_version')!r} (written by "
            f"semistatic {manifest.get('project_version')!r}); this version reads "
            f"{FORMAT_VERSION}: record it again",
        )
    check_manifest(manifest, path)
    return Recording(path, manifest, read_scans(path, manifest))
