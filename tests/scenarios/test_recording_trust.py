"""Recordings and storages are validated, never trusted.

The fast tests build a recording by hand from the documented format (the arrays'
names, dtypes and shapes, the manifest's keys), independent of the writer, and tamper with
it: each tampered case is one :class:`SpecError` naming ``--recording`` and the key, never
another exception. Hypothesis flips bytes, drops keys and retypes values. The slow test
tampers with a genuine ``run --record`` recording and runs ``tune`` on it.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import sqlite3
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import optuna
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scenarios.logs.recording import FORMAT, FORMAT_VERSION, read_recording
from scenarios.tuning.storage import check_storage
from semistatic.errors import SpecError
from tests.scenarios.tiny_world import write_tiny

REPO = Path(__file__).resolve().parents[2]
SCANS, BEAMS = 4, 6


def _arrays() -> dict[str, np.ndarray]:
    ranges = np.full((SCANS, BEAMS), 2.0)
    ranges[0, 0] = np.inf  # no return, as the writer writes it
    header = np.tile([-1.0, 0.4, 0.05, 20.0, 0.0], (SCANS, 1))
    header[:, 4] = np.arange(SCANS) * 0.08
    return {
        "ranges": ranges, "header": header,
        **{name: np.zeros((SCANS, 3)) for name in ("scan_pose", "sensor_pose", "ekf_pose",
                                                   "odom_pose")},
        "ekf_covariance": np.tile(np.eye(3), (SCANS, 1, 1)),
        "lap": np.array([1, 1, 2, 2]), "segment": np.zeros(SCANS, dtype=np.int64),
        "lap_scans": np.array([1, 2, 1, 2]), "layout": np.zeros(SCANS, dtype=np.int64),
        "people": np.array([[1.0, 2.0]]), "people_offsets": np.array([0, 1, 1, 1, 1]),
    }


def _manifest() -> dict:
    return {
        "format": FORMAT, "format_version": FORMAT_VERSION, "project_version": "0",
        "scenario": "tiny", "seed": 3, "laps": 2, "policy": "conservative",
        "scenario_source": "tiny.toml", "fingerprint": {"seed": "abc"},
        "segments": ["corridor"],
        "layouts": [[{"name": "carton", "size": [0.5, 0.4, 0.6], "pose": [2.6, -1.0, 0.0],
                      "remission": 0.3}]],
        "lap_layouts": [{"lap": 1, "start": 0, "end": 0}, {"lap": 2, "start": 0, "end": 0}],
        "metrics": {"laps": 2}, "scans": SCANS, "beams": BEAMS,
    }


def _write(folder: Path, arrays: dict, manifest: dict, *, digest: bool = True) -> Path:
    """Write a recording; ``digest``: store the npz's true sha256 (a forger's recompute)."""
    folder.mkdir(parents=True, exist_ok=True)
    np.savez(folder / "scans.npz", **arrays)
    if digest:
        manifest = {**manifest,
                    "scans_sha256": hashlib.sha256((folder / "scans.npz").read_bytes()).hexdigest()}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


def _refused(folder: Path, *fragments: str) -> str:
    with pytest.raises(SpecError) as caught:
        read_recording(folder)
    line = str(caught.value)
    assert line.startswith("--recording: "), line
    assert "\n" not in line, line
    for fragment in fragments:
        assert fragment in line, line
    return line


def test_a_hand_written_recording_of_the_documented_format_is_read(tmp_path):
    recording = read_recording(_write(tmp_path / "rec", _arrays(), _manifest()))
    assert recording.arrays["ranges"].shape == (SCANS, BEAMS)
    assert recording.manifest["beams"] == BEAMS


def _with(name, value):
    arrays = _arrays()
    if value is None:
        del arrays[name]
    else:
        arrays[name] = value
    return arrays


TAMPERED_ARRAYS = {
    "int8 ranges": (_with("ranges", np.ones((SCANS, BEAMS), dtype=np.int8)),
                    ["scans.npz: ranges", "must be float64 of shape (4, 6), got int8"]),
    "flattened ranges": (_with("ranges", np.ones(SCANS * BEAMS)),
                         ["ranges", "shape (24,)"]),
    "all-NaN ranges": (_with("ranges", np.full((SCANS, BEAMS), np.nan)),
                       ["ranges", "scan 0", "no NaN"]),
    "negative range": (_with("ranges", np.full((SCANS, BEAMS), -1.0)), ["ranges"]),
    "beyond range_max": (_with("ranges", np.full((SCANS, BEAMS), 25.0)), ["range_max"]),
    "missing member": (_with("people_offsets", None), ["people_offsets", "missing array"]),
    "segment out of range": (_with("segment", np.array([0, 0, 1, 0])),
                             ["segment", "indices must be 0..0, got 0..1"]),
    "layout out of range": (_with("layout", np.array([0, -1, 0, 0])), ["layout"]),
    "lap out of range": (_with("lap", np.array([1, 1, 2, 3])), ["lap", "1..2"]),
    "NaN pose": (_with("ekf_pose", np.full((SCANS, 3), np.nan)), ["ekf_pose", "NaN"]),
    "people offsets past the rows": (_with("people_offsets", np.array([0, 1, 2, 2, 2])),
                                     ["people_offsets", "from 0 to 1"]),
    "object array": (_with("people", np.array([[1, "x"]], dtype=object)), ["cannot read"]),
}


@pytest.mark.parametrize("case", TAMPERED_ARRAYS)
def test_tampered_arrays_with_a_forged_digest_are_refused(tmp_path, case):
    arrays, fragments = TAMPERED_ARRAYS[case]
    if case == "object array":
        # np.savez pickles object arrays; the reader must refuse them without unpickling.
        folder = tmp_path / "rec"
        folder.mkdir()
        with zipfile.ZipFile(folder / "scans.npz", "w") as archive:
            for name, array in _arrays().items():
                buffer = io.BytesIO()
                np.save(buffer, arrays[name] if name == "people" else array,
                        allow_pickle=True)
                archive.writestr(f"{name}.npy", buffer.getvalue())
        digest = hashlib.sha256((folder / "scans.npz").read_bytes()).hexdigest()
        (folder / "manifest.json").write_text(json.dumps({**_manifest(),
                                                          "scans_sha256": digest}))
    else:
        folder = _write(tmp_path / "rec", arrays, _manifest())
    _refused(folder, *fragments)


def test_a_member_header_promising_more_than_it_holds_is_refused_before_allocation(tmp_path):
    folder = _write(tmp_path / "rec", _arrays(), _manifest())
    header = np.lib.format.header_data_from_array_1_0(np.zeros((SCANS, BEAMS)))
    header["shape"] = (10**7, 10**6)  # 80 TB of float64
    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(buffer, header)
    with zipfile.ZipFile(folder / "scans.npz", "a") as archive:
        archive.writestr("ranges_big.npy", buffer.getvalue() + bytes(64))
    digest = hashlib.sha256((folder / "scans.npz").read_bytes()).hexdigest()
    (folder / "manifest.json").write_text(json.dumps({**_manifest(), "scans_sha256": digest}))
    _refused(folder, "scans.npz", "ranges_big.npy", "declares 80000000000000 bytes")


def test_a_truncated_npz_is_one_line_naming_the_file(tmp_path):
    folder = _write(tmp_path / "rec", _arrays(), _manifest())
    data = (folder / "scans.npz").read_bytes()
    (folder / "scans.npz").write_bytes(data[: len(data) // 2])
    _refused(folder, "scans.npz", "sha256 differs")
    digest = hashlib.sha256(data[: len(data) // 2]).hexdigest()
    (folder / "manifest.json").write_text(json.dumps({**_manifest(), "scans_sha256": digest}))
    _refused(folder, "scans.npz", "cannot read")


MANIFEST_TAMPERS = {
    "dropped key": (lambda m: m.pop("segments"), ["manifest.json: segments: missing"]),
    "string seed": (lambda m: m.update(seed="3"), ["seed: must be a JSON int, got str"]),
    "bool laps": (lambda m: m.update(laps=True), ["laps: must be a JSON int, got bool"]),
    "layouts a dict": (lambda m: m.update(layouts={}), ["layouts: must be a JSON list"]),
    "box retyped": (lambda m: m["layouts"][0][0].update(size="big"), ["layouts[0][0].size"]),
    "box with a stray key": (lambda m: m["layouts"][0][0].update(colour=1), ["colour"]),
    "lap layout past the layouts": (lambda m: m["lap_layouts"][0].update(end=5),
                                    ["lap_layouts[0].end", "indexes no layout"]),
    "beams off": (lambda m: m.update(beams=7), ["ranges", "shape (4, 7)"]),
    "unknown key": (lambda m: m.update(extra=1), ["extra: unknown key"]),
}


@pytest.mark.parametrize("case", MANIFEST_TAMPERS)
def test_tampered_manifests_are_refused_naming_the_key(tmp_path, case):
    tamper, fragments = MANIFEST_TAMPERS[case]
    folder = _write(tmp_path / "rec", _arrays(), _manifest())
    manifest = json.loads((folder / "manifest.json").read_text())
    tamper(manifest)
    (folder / "manifest.json").write_text(json.dumps(manifest))
    _refused(folder, *fragments)


def test_an_edited_npz_is_refused_by_its_digest(tmp_path):
    folder = _write(tmp_path / "rec", _arrays(), _manifest())
    arrays = _arrays()
    arrays["ranges"][1, 1] = 3.0  # a valid value: only the digest can tell
    np.savez(folder / "scans.npz", **arrays)
    _refused(folder, "scans.npz", "sha256 differs from the manifest's")


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_flipped_byte_or_retyped_value_is_one_spec_error(tmp_path_factory, data):
    folder = _write(tmp_path_factory.mktemp("rec"), _arrays(), _manifest())
    target = data.draw(st.sampled_from(["scans.npz", "manifest.json"]))
    raw = bytearray((folder / target).read_bytes())
    if target == "manifest.json" and data.draw(st.booleans()):
        manifest = json.loads(raw)
        key = data.draw(st.sampled_from(sorted(manifest)))
        manifest[key] = data.draw(st.one_of(st.none(), st.integers(), st.text(max_size=3),
                                            st.lists(st.integers(), max_size=2),
                                            st.dictionaries(st.text(max_size=2),
                                                            st.integers(), max_size=2)))
        (folder / target).write_text(json.dumps(manifest))
    else:
        # Distinct positions: flipping one byte twice could restore it.
        for position in data.draw(st.sets(st.integers(0, len(raw) - 1), min_size=1,
                                          max_size=4)):
            raw[position] ^= data.draw(st.integers(1, 255))
        (folder / target).write_bytes(bytes(raw))
    line = None
    try:
        read_recording(folder)
    except SpecError as error:  # any other exception fails the test
        line = str(error)
    if target == "scans.npz":
        assert line is not None, "a changed scans.npz must fail its digest"
    if line is not None:
        assert line.startswith("--recording: "), line
        assert "\n" not in line, line
    # A manifest may still be accepted when the change kept it what the writer writes
    # (a flipped byte inside the project version string, say).


# --- storages ---------------------------------------------------------------------------

def test_a_foreign_sqlite_database_is_refused_untouched(tmp_path):
    mine = tmp_path / "mine.db"
    with sqlite3.connect(mine) as db:
        db.execute("CREATE TABLE notes (text)")
        db.execute("INSERT INTO notes VALUES ('keep me')")
    db.close()
    before = mine.read_bytes()
    with pytest.raises(SpecError, match=r"is a database of another program \(tables: notes\)"):
        check_storage(f"sqlite:///{mine}")
    assert mine.read_bytes() == before
    assert sorted(path.name for path in tmp_path.iterdir()) == ["mine.db"]


def test_empty_new_and_optuna_storages_are_accepted(tmp_path):
    (tmp_path / "empty.db").touch()
    check_storage(f"sqlite:///{tmp_path / 'empty.db'}")
    check_storage(f"sqlite:///{tmp_path / 'new.db'}")
    optuna.create_study(storage=f"sqlite:///{tmp_path / 'study.db'}", study_name="s")
    check_storage(f"sqlite:///{tmp_path / 'study.db'}")


def test_not_sqlite_fifo_and_read_only_storages_are_refused(tmp_path):
    (tmp_path / "notes.db").write_text("not a database")
    with pytest.raises(SpecError, match="is not an SQLite database"):
        check_storage(f"sqlite:///{tmp_path / 'notes.db'}")
    os.mkfifo(tmp_path / "fifo.db")
    with pytest.raises(SpecError, match="is a FIFO"):
        check_storage(f"sqlite:///{tmp_path / 'fifo.db'}")
    optuna.create_study(storage=f"sqlite:///{tmp_path / 'study.db'}", study_name="s")
    (tmp_path / "study.db").chmod(0o444)
    with pytest.raises(SpecError, match="is read-only"):
        check_storage(f"sqlite:///{tmp_path / 'study.db'}")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        with pytest.raises(SpecError, match="read-only; name a file in a writable directory"):
            check_storage(f"sqlite:///{locked / 'new.db'}")
    finally:
        locked.chmod(0o755)


# --- slow: the commands on a genuine recording and a foreign storage ---------------------

def _semistatic(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "scenarios", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=900, check=False)


@pytest.mark.slow
def test_tune_refuses_a_tampered_recording_and_a_foreign_storage_in_one_line(tmp_path):
    write_tiny(tmp_path)
    done = _semistatic(["run", "tiny.toml", "--out", "out", "--record", "rec",
                        "--no-figures"], tmp_path)
    assert done.returncode == 0, done.stderr
    read_recording(tmp_path / "rec")  # the genuine one is accepted
    tune = ["tune", "tiny.toml", "--recording", "rec", "--param", "mapper.gate=0.1:0.2",
            "--trials", "1", "--out", "t"]
    manifest = json.loads((tmp_path / "rec" / "manifest.json").read_text())
    scans = (tmp_path / "rec" / "scans.npz").read_bytes()
    edits = {
        "manifest.json": json.dumps({**manifest, "laps": "2"}).encode(),
        "scans.npz": scans[:100] + bytes([scans[100] ^ 1]) + scans[101:],
    }
    for name, damaged in edits.items():
        original = (tmp_path / "rec" / name).read_bytes()
        (tmp_path / "rec" / name).write_bytes(damaged)
        done = _semistatic(tune, tmp_path)
        assert done.returncode == 2, done.stderr
        assert done.stderr.count("\n") == 1, done.stderr
        assert done.stderr.startswith("error: --recording: "), done.stderr
        assert not (tmp_path / "t").exists()
        (tmp_path / "rec" / name).write_bytes(original)
    mine = tmp_path / "mine.db"
    with sqlite3.connect(mine) as db:
        db.execute("CREATE TABLE notes (text)")
    db.close()
    before = mine.read_bytes()
    done = _semistatic([*tune, "--storage", f"sqlite:///{mine}"], tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    assert "not an Optuna storage" in done.stderr
    assert mine.read_bytes() == before
