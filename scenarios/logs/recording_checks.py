"""Check a recording read back: its manifest's schema, the digest of its scans, every array.

A recording (:mod:`scenarios.logs.recording`) is user data: it may be truncated, edited or
forged. Nothing in it is trusted: :func:`check_manifest` checks every key and type of
``manifest.json``, :func:`read_scans` checks the size and the sha256 digest of
``scans.npz`` against the manifest before numpy reads it (without pickle), that every
member's header fits the member (no allocation a member cannot fill), then
:func:`check_arrays` checks each array's dtype, shape, finiteness and indices against the
manifest. Any problem is one :class:`~semistatic.errors.SpecError` naming ``--recording``
and the key.

Examples
--------
>>> check_manifest({"format": "semistatic-recording", "format_version": 2}, "rec")
Traceback (most recent call last):
...
semistatic.errors.SpecError: --recording: manifest.json: project_version: missing; rec is \
damaged: record it again
"""

from __future__ import annotations

import hashlib
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from semistatic.errors import SpecError
from semistatic.inputs import MAX_RECORDING_BYTES, check_regular_file
from semistatic.types import MAX_BEAMS
from semistatic.validation import from_table
from worlds.spec import BoxSpec

__all__ = [
    "MANIFEST", "RECORDING_OPTION", "SCANS", "check_arrays", "check_manifest", "file_digest",
    "read_scans",
]

RECORDING_OPTION = "--recording"
MANIFEST = "manifest.json"
SCANS = "scans.npz"

# Top-level keys of manifest.json and their JSON types (bool is not an int here).
MANIFEST_TYPES: dict[str, type] = {
    "format": str, "format_version": int, "project_version": str, "scenario": str,
    "seed": int, "laps": int, "policy": str, "scenario_source": str, "fingerprint": dict,
    "segments": list, "layouts": list, "lap_layouts": list, "metrics": dict,
    "scans": int, "beams": int, "scans_sha256": str,
}

POSES = ("scan_pose", "sensor_pose", "ekf_pose", "odom_pose")
INDICES = ("lap", "segment", "lap_scans", "layout")
HEADER_COLUMNS = 5  # angle_min, angle_increment, range_min, range_max, stamp
_DIGEST_CHUNK = 1 << 20
_HEADER_READERS = {(1, 0): np.lib.format.read_array_header_1_0,
                   (2, 0): np.lib.format.read_array_header_2_0}


def _damaged(key: str, what: str, path: str | Path) -> SpecError:
    return SpecError(RECORDING_OPTION, f"{MANIFEST}: {key}" if key else MANIFEST,
                     f"{what}; {path} is damaged: record it again")


def _typed(value: Any, kind: type) -> bool:
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, kind)


def check_manifest(manifest: Mapping[str, Any], path: str | Path) -> None:
    """Raise :class:`SpecError` unless ``manifest`` has every key, of its type, and no other.

    Besides the types: the counts are positive (at most ``MAX_BEAMS`` beams), segments
    are strings, every layout's box is a valid :class:`~worlds.spec.BoxSpec` table, each
    lap's layouts index ``layouts``, the fingerprint maps names to digests.

    Examples
    --------
    >>> check_manifest([], "rec")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --recording: manifest.json: not a JSON object; rec is \
damaged: record it again
    """
    if not isinstance(manifest, Mapping):
        raise _damaged("", "not a JSON object", path)
    for key, kind in MANIFEST_TYPES.items():
        if key not in manifest:
            raise _damaged(key, "missing", path)
        if not _typed(manifest[key], kind):
            raise _damaged(key, f"must be a JSON {kind.__name__}, got "
                           f"{type(manifest[key]).__name__}", path)
    unknown = sorted(set(manifest) - set(MANIFEST_TYPES))
    if unknown:
        raise _damaged(unknown[0], "unknown key", path)
    if not 1 <= manifest["beams"] <= MAX_BEAMS:
        raise _damaged("beams", f"must be 1..{MAX_BEAMS}, got {manifest['beams']}", path)
    if manifest["scans"] < 1 or manifest["laps"] < 1:
        raise _damaged("scans", "a recording holds at least one lap and one scan", path)
    if not manifest["segments"] or not all(isinstance(s, str) for s in manifest["segments"]):
        raise _damaged("segments", "must be a non-empty list of segment names", path)
    if not all(isinstance(k, str) and isinstance(v, str)
               for k, v in manifest["fingerprint"].items()):
        raise _damaged("fingerprint", "must map field names to digests (strings)", path)
    for index, boxes in enumerate(manifest["layouts"]):
        if not isinstance(boxes, list):
            raise _damaged(f"layouts[{index}]", "must be a list of boxes", path)
        for number, box in enumerate(boxes):
            # The world's own validation: every key, type and bound of a box.
            from_table(BoxSpec, box, file=RECORDING_OPTION,
                       key=f"{MANIFEST}: layouts[{index}][{number}]")
    for index, lap_layout in enumerate(manifest["lap_layouts"]):
        key = f"lap_layouts[{index}]"
        if not isinstance(lap_layout, dict) or set(lap_layout) != {"lap", "start", "end"}:
            raise _damaged(key, "must be a table of lap, start and end", path)
        if not all(_typed(value, int) for value in lap_layout.values()):
            raise _damaged(key, "lap, start and end must be integers", path)
        if not 1 <= lap_layout["lap"] <= manifest["laps"]:
            raise _damaged(f"{key}.lap", f"must be 1..{manifest['laps']}", path)
        for name in ("start", "end"):
            if not 0 <= lap_layout[name] < len(manifest["layouts"]):
                raise _damaged(f"{key}.{name}", f"indexes no layout (there are "
                               f"{len(manifest['layouts'])})", path)


def file_digest(path: str | Path) -> str:
    """Return the sha256 hex digest of the file ``path``, read in 1 MiB chunks.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> folder = tempfile.TemporaryDirectory()
    >>> _ = (pathlib.Path(folder.name) / "x").write_bytes(b"abc")
    >>> file_digest(pathlib.Path(folder.name) / "x")[:16]
    'ba7816bf8f01cfea'
    >>> folder.cleanup()
    """
    hasher = hashlib.sha256()
    with open(path, "rb") as stream:
        while chunk := stream.read(_DIGEST_CHUNK):
            hasher.update(chunk)
    return hasher.hexdigest()


def _check_member(archive: zipfile.ZipFile, name: str) -> None:
    """Refuse a member whose header promises more data than the member holds."""
    info = archive.getinfo(name)
    with archive.open(info) as stream:
        version = np.lib.format.read_magic(stream)
        if version not in _HEADER_READERS:
            raise ValueError(f"member {name}: npy format version {version}, the writer's "
                             "are 1.0 and 2.0")
        shape, _, dtype = _HEADER_READERS[version](stream)
        needed = int(np.prod(shape, dtype=object)) * dtype.itemsize
        if dtype.hasobject or needed > info.file_size:
            raise ValueError(f"member {name}: its header declares {needed} bytes of "
                             f"{dtype}, the member holds {info.file_size}")


def read_scans(path: str | Path, manifest: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """Return the arrays of ``path / scans.npz`` once its size, digest and headers hold.

    The file is a regular file of at most ``MAX_RECORDING_BYTES``, its sha256 is the
    manifest's ``scans_sha256``, it is read without pickle, and every member's header
    fits its data; then :func:`check_arrays`.

    Examples
    --------
    >>> read_scans("/nonexistent", {})
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --recording: scans.npz: no such file
    """
    scans = Path(path) / SCANS
    check_regular_file(scans, limit=MAX_RECORDING_BYTES, what="recording's scans.npz",
                       file=RECORDING_OPTION, key=SCANS)
    try:
        if file_digest(scans) != manifest["scans_sha256"]:
            raise SpecError(RECORDING_OPTION, SCANS, f"{scans} is not the file the "
                            "recording wrote (its sha256 differs from the manifest's); "
                            "record it again")
        with zipfile.ZipFile(scans) as archive:
            for name in archive.namelist():
                _check_member(archive, name)
        with np.load(scans, allow_pickle=False) as data:
            arrays = {name.removesuffix(".npy"): data[name] for name in data.files}
    except SpecError:
        raise
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile,
            zipfile.LargeZipFile) as error:
        raise SpecError(RECORDING_OPTION, SCANS, f"cannot read {scans}: {error}") from None
    check_arrays(arrays, manifest, path)
    return arrays


def _expect(arrays: Mapping[str, np.ndarray], name: str, dtype: type, shape: tuple,
            path: str | Path) -> np.ndarray:
    if name not in arrays:
        raise SpecError(RECORDING_OPTION, f"{SCANS}: {name}",
                        f"missing array; {path} is damaged: record it again")
    array = arrays[name]
    if array.dtype != dtype or array.shape != shape:
        raise SpecError(RECORDING_OPTION, f"{SCANS}: {name}",
                        f"must be {np.dtype(dtype)} of shape {shape}, got {array.dtype} of "
                        f"shape {array.shape}; {path} is damaged: record it again")
    if array.dtype.kind == "f" and name != "ranges" and not np.all(np.isfinite(array)):
        raise SpecError(RECORDING_OPTION, f"{SCANS}: {name}",
                        f"holds NaN or inf; {path} is damaged: record it again")
    return array


def _refuse(name: str, what: str, path: str | Path) -> SpecError:
    return SpecError(RECORDING_OPTION, f"{SCANS}: {name}",
                     f"{what}; {path} is damaged: record it again")


def check_arrays(arrays: Mapping[str, np.ndarray], manifest: Mapping[str, Any],
                 path: str | Path) -> None:
    """Raise :class:`SpecError` unless the arrays are what the writer writes.

    Ranges float64 ``(scans, beams)`` as the manifest says, each in ``[0, range_max]`` or
    ``inf`` (never NaN); headers, poses and covariances finite float64 of their shapes;
    laps, segments and layouts int64 indices within the manifest's; people offsets rising
    from 0 to the number of people rows.

    Examples
    --------
    >>> manifest = {"scans": 1, "beams": 2}
    >>> check_arrays({"ranges": np.zeros(2, dtype=np.int8)}, manifest, "rec")
    Traceback (most recent call last):
    ...
    semistatic.errors.SpecError: --recording: scans.npz: ranges: must be float64 of shape \
(1, 2), got int8 of shape (2,); rec is damaged: record it again
    """
    count, beams = manifest["scans"], manifest["beams"]
    ranges = _expect(arrays, "ranges", np.float64, (count, beams), path)
    header = _expect(arrays, "header", np.float64, (count, HEADER_COLUMNS), path)
    for name in POSES:
        _expect(arrays, name, np.float64, (count, 3), path)
    _expect(arrays, "ekf_covariance", np.float64, (count, 3, 3), path)
    indices = {name: _expect(arrays, name, np.int64, (count,), path) for name in INDICES}
    limits = {"lap": (1, manifest["laps"]), "segment": (0, len(manifest["segments"]) - 1),
              "lap_scans": (1, count), "layout": (0, len(manifest["layouts"]) - 1)}
    for name, (low, high) in limits.items():
        values = indices[name]
        if values.min() < low or values.max() > high:
            raise _refuse(name, f"indices must be {low}..{high}, got {values.min()}.."
                          f"{values.max()}", path)
    if not (np.all(header[:, 1] > 0) and np.all(header[:, 2] >= 0)
            and np.all(header[:, 2] < header[:, 3])):
        raise _refuse("header", "needs angle increments > 0 and 0 <= range_min < range_max",
                      path)
    with np.errstate(invalid="ignore"):
        valid = (ranges >= 0) & ((ranges <= header[:, 3:4]) | (ranges == np.inf))
    if not np.all(valid):
        scan = int(np.flatnonzero(~valid.all(axis=1))[0])
        raise _refuse("ranges", f"scan {scan}: ranges must be in [0, range_max] or inf "
                      "(no NaN, nothing negative)", path)
    people = arrays.get("people")
    if people is None or people.dtype != np.float64 or people.ndim != 2 \
            or people.shape[1] != 2 or not np.all(np.isfinite(people)):
        raise _refuse("people", "must be finite float64 of shape (rows, 2)", path)
    offsets = _expect(arrays, "people_offsets", np.int64, (count + 1,), path)
    if offsets[0] != 0 or offsets[-1] != len(people) or np.any(np.diff(offsets) < 0):
        raise _refuse("people_offsets", f"must rise from 0 to {len(people)}", path)
