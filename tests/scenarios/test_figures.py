"""The figures of a closed-loop run: real PNGs, clear errors, atomic writes, no pyplot leaks."""

import dataclasses
import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.image import imread

from robots.path import SplinePath
from robots.presets import get_preset
from scenarios.bench.records import LapLog, RunLog
from scenarios.bench.safety_record import SafetyRecord
from scenarios.results import run_figures
from scenarios.results.figures import ekf as ekf_figure
from scenarios.results.figures import events as events_figure
from scenarios.results.figures import laps as lap_figures
from scenarios.results.figures import (
    plot_detection_scores,
    plot_ekf_corrections,
    plot_lap_times,
    plot_polygonal_map,
    plot_run_events,
    plot_tangent_histograms,
)
from scenarios.results.figures import polygonal_map as map_figure
from scenarios.results.figures import sharing as sharing_figure
from scenarios.results.figures import tangents as tangents_figure
from scenarios.spec.layout import scenario_world
from scenarios.spec.load import load_scenario
from semistatic.colours import STATUS_COLOURS
from worlds.load import load_world

MIN_PNG_BYTES = 5_000
MIN_DISTINCT_COLOURS = 5
MIN_INK_FRACTION = 0.01  # of pixels that are not white
TAB_RED = np.array([0.839, 0.153, 0.157])
NEW_BLUE = np.array(STATUS_COLOURS["new"])
COLOUR_TOLERANCE = 0.03


@pytest.fixture(scope="module")
def world():
    return load_world("sim1")


def map_inputs(world, status="confirmed"):
    rng = np.random.default_rng(3)
    spline = SplinePath(world.path.knots)
    truth = spline.pose(np.linspace(0.0, spline.length, 300))
    polylines = [
        {
            "points": np.array([wall.start, wall.end]),
            "segment": "aisle",
            "status": status,
            "id": index,
        }
        for index, wall in enumerate(world.walls)
    ]
    return {
        "world": world,
        "map_polylines": polylines,
        "truth_outlines": {box.name: box.corners() for box in world.boxes},
        "trajectory": truth,
        "estimate": truth + rng.normal(0.0, 0.01, truth.shape),
    }


def ekf_inputs(count=80):
    rng = np.random.default_rng(7)
    stamps = np.linspace(0.0, 20.0, count)
    sigmas = np.column_stack(
        [0.004 + 0.01 * np.exp(-stamps), 0.005 + 0.01 * np.exp(-stamps), np.full(count, 0.02)]
    )
    return stamps, rng.normal(0.0, sigmas), sigmas


LAPS = {"conservative": [40.0, 41.0, 40.5], "adaptive": [38.0, 33.0, 32.5]}
SCORES = [
    {"lap": 1, "precision": math.nan, "recall": math.nan, "f1": math.nan},
    {"lap": 2, "precision": 0.8, "recall": 0.6, "f1": 0.69},
    {"lap": 3, "precision": 1.0, "recall": 0.9, "f1": 0.95},
]
CORNER = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 1.5]])


def render(name, path, world):
    """Draw figure ``name`` with valid synthetic data into ``path``."""
    if name == "tangent":
        return plot_tangent_histograms(CORNER, CORNER[::-1] * 1.5, path, title="pair 3")
    if name == "map":
        inputs = map_inputs(world)
        return plot_polygonal_map(inputs.pop("world"), inputs.pop("map_polylines"), path, **inputs)
    if name == "ekf":
        return plot_ekf_corrections(*ekf_inputs(), path, title="sim1")
    if name == "laps":
        return plot_lap_times(LAPS, path, stops={"adaptive": [0, 2, 0]})
    if name == "events":
        return plot_run_events(EVENT_LAPS, path, speeds=EVENT_SPEEDS, events=EVENTS)
    assert name == "scores"
    return plot_detection_scores(SCORES, path)


EVENT_LAPS = [{"lap": 1, "duration_s": 20.0, "stops": 1, "slowdowns": 2},
              {"lap": 2, "duration_s": 18.0, "latencies": {"crate": 4}}]
EVENT_SPEEDS = {1: (np.linspace(0.0, 20.0, 50), np.full(50, 0.4))}
EVENTS = [{"lap": 1, "t": 7.5, "kind": "stop"},
          {"lap": 2, "t": 3.0, "kind": "new_object", "label": "aisle#4"},
          {"lap": 2, "t": 9.0, "kind": "infraction", "label": "near miss"}]

FIGURES = ("tangent", "map", "ekf", "laps", "scores", "events")


@pytest.mark.parametrize("name", FIGURES)
def test_writes_a_png_with_visible_content(name, world, tmp_path):
    before = plt.get_fignums()
    out = render(name, tmp_path / "nested" / f"{name}.png", world)

    assert out == tmp_path / "nested" / f"{name}.png"
    assert out.stat().st_size > MIN_PNG_BYTES
    image = imread(out)[..., :3]
    assert image.shape[0] > 300
    assert image.shape[1] > 300
    rgb = (image * 255).astype(np.int64)
    colours = np.unique(rgb[..., 0] << 16 | rgb[..., 1] << 8 | rgb[..., 2])
    assert colours.size >= MIN_DISTINCT_COLOURS
    ink = np.any(image < 0.95, axis=-1).mean()
    assert ink > MIN_INK_FRACTION
    # Only the PNG: no temporary file next to it, and no figure left in pyplot's registry.
    assert sorted(p.name for p in out.parent.iterdir()) == [f"{name}.png"]
    assert plt.get_fignums() == before


@pytest.mark.parametrize("name", FIGURES)
def test_same_input_gives_the_same_bytes(name, world, tmp_path):
    first = render(name, tmp_path / "a.png", world)
    second = render(name, tmp_path / "b.png", world)
    assert first.read_bytes() == second.read_bytes()


@pytest.mark.parametrize("name", FIGURES)
def test_failure_while_saving_keeps_the_old_file_and_leaves_no_temporary(
    name, world, tmp_path, monkeypatch
):
    out = tmp_path / f"{name}.png"
    out.write_bytes(b"previous picture")

    def savefig_that_breaks(self, stream, **kwargs):
        stream.write(b"\x89PNG half a picture")
        raise RuntimeError("disk full")

    monkeypatch.setattr(Figure, "savefig", savefig_that_breaks)
    with pytest.raises(RuntimeError, match="disk full"):
        render(name, out, world)
    assert out.read_bytes() == b"previous picture"
    assert [p.name for p in tmp_path.iterdir()] == [out.name]


def test_failure_on_a_new_path_writes_nothing(world, tmp_path, monkeypatch):
    def savefig_that_breaks(self, stream, **kwargs):
        stream.write(b"\x89PNG half")
        raise OSError("no space left on device")

    monkeypatch.setattr(Figure, "savefig", savefig_that_breaks)
    with pytest.raises(OSError, match="no space"):
        render("laps", tmp_path / "laps.png", world)
    assert list(tmp_path.iterdir()) == []


def test_bad_input_leaves_an_existing_figure_untouched(tmp_path):
    out = tmp_path / "ekf.png"
    out.write_bytes(b"previous picture")
    stamps, corrections, sigmas = ekf_inputs()
    with pytest.raises(ValueError, match="corrections"):
        plot_ekf_corrections(stamps, corrections[:-1], sigmas, out)
    assert out.read_bytes() == b"previous picture"
    assert [p.name for p in tmp_path.iterdir()] == ["ekf.png"]


def test_written_png_is_readable_by_others(tmp_path):
    out = plot_detection_scores(SCORES, tmp_path / "scores.png")
    assert out.stat().st_mode & 0o044 == 0o044


def tangent_call(p0, p1):
    return lambda path, world: plot_tangent_histograms(p0, p1, path)


def map_call(**changes):
    def call(path, world):
        inputs = map_inputs(world) | changes
        return plot_polygonal_map(inputs.pop("world"), inputs.pop("map_polylines"), path, **inputs)

    return call


def ekf_call(transform):
    return lambda path, world: plot_ekf_corrections(*transform(*ekf_inputs()), path)


def laps_call(lap_times, stops=None):
    return lambda path, world: plot_lap_times(lap_times, path, stops=stops)


def scores_call(rows):
    return lambda path, world: plot_detection_scores(rows, path)


BAD_INPUTS = {
    "tangent: not (N, 2)": (tangent_call(np.zeros((3, 3)), CORNER), "p0: expected an \\(N, 2\\)"),
    "tangent: one vertex": (tangent_call(CORNER, [[1.0, 2.0]]), "p1: needs at least 2 vertices"),
    "tangent: zero length": (tangent_call(CORNER, [[1.0, 2.0], [1.0, 2.0]]), "p1: has zero length"),
    "tangent: nan vertex": (tangent_call([[0.0, 0.0], [np.nan, 1.0]], CORNER), "p0: .*finite"),
    "map: unknown status": (
        map_call(map_polylines=[{"points": CORNER, "status": "seen"}]),
        "map_polylines\\[0\\].status: must be one of",
    ),
    "map: missing points": (
        map_call(map_polylines=[{"status": "new"}]),
        "map_polylines\\[0\\]: missing key 'points'",
    ),
    "map: polyline not a dict": (map_call(map_polylines=[CORNER]), "map_polylines\\[0\\]"),
    "map: trajectory (N, 4)": (map_call(trajectory=np.zeros((5, 4))), "trajectory: expected"),
    "map: empty estimate": (map_call(estimate=np.zeros((0, 3))), "estimate: expected"),
    "map: two-point outline": (
        map_call(truth_outlines={"crate": [[0, 0], [1, 1]]}),
        "truth_outlines\\['crate'\\]: needs at least 3",
    ),
    "ekf: fewer corrections than stamps": (
        ekf_call(lambda t, c, s: (t, c[:-1], s)),
        "corrections: expected shape \\(80, 3\\)",
    ),
    "ekf: fewer sigmas than stamps": (
        ekf_call(lambda t, c, s: (t, c, s[:-2])),
        "sigmas: expected shape \\(80, 3\\)",
    ),
    "ekf: no updates": (ekf_call(lambda t, c, s: (t[:0], c[:0], s[:0])), "stamps: expected a non"),
    "ekf: stamps go back": (ekf_call(lambda t, c, s: (t[::-1], c, s)), "stamps: must not decrease"),
    "ekf: negative sigma": (ekf_call(lambda t, c, s: (t, c, -s)), "sigmas: .* >= 0"),
    "ekf: nan correction": (
        ekf_call(lambda t, c, s: (t, np.where(t > 5.0, np.nan, 0.0)[:, None] * c, s)),
        "corrections: must be finite",
    ),
    "ekf: reinitialized of wrong length": (
        lambda path, world: plot_ekf_corrections(
            *ekf_inputs(), path, reinitialized=np.zeros(79, dtype=bool)
        ),
        "reinitialized: expected \\(80,\\) booleans",
    ),
    "ekf: reinitialized not booleans": (
        lambda path, world: plot_ekf_corrections(*ekf_inputs(), path, reinitialized=np.zeros(80)),
        "reinitialized: expected",
    ),
    "laps: different lap counts": (
        laps_call({"conservative": [40.0, 41.0], "adaptive": [32.0]}),
        "lap_times\\['adaptive'\\]: has 1 laps but the first policy has 2",
    ),
    "laps: no policies": (laps_call({}), "lap_times: expected a non-empty dict"),
    "laps: negative time": (laps_call({"adaptive": [30.0, -1.0]}), "must be finite and > 0"),
    "laps: stops of unknown policy": (
        laps_call(LAPS, stops={"adaptiv": [0, 0, 0]}),
        "stops: unknown policy 'adaptiv'",
    ),
    "laps: stops too short": (laps_call(LAPS, stops={"adaptive": [0, 1]}), "expected 3 stop"),
    "laps: fractional stops": (laps_call(LAPS, stops={"adaptive": [0, 1.5, 0]}), "integers >= 0"),
    "scores: empty": (scores_call([]), "per_lap: expected a non-empty list"),
    "scores: missing f1": (
        scores_call([{"lap": 1, "precision": 1.0, "recall": 1.0}]),
        "per_lap\\[0\\]: missing key\\(s\\) \\['f1'\\]",
    ),
    "scores: repeated lap": (scores_call([SCORES[1], SCORES[1]]), "lap 2 appears twice"),
    "scores: above one": (scores_call([{**SCORES[1], "f1": 1.3}]), "per_lap\\[0\\].f1: must be in"),
    "scores: lap not an integer": (
        scores_call([{**SCORES[1], "lap": 2.5}]),
        "per_lap\\[0\\].lap: must be an integer",
    ),
}


@pytest.mark.parametrize("case", BAD_INPUTS, ids=list(BAD_INPUTS))
def test_bad_input_raises_a_clear_value_error_and_writes_nothing(case, world, tmp_path):
    call, message = BAD_INPUTS[case]
    with pytest.raises(ValueError, match=message):
        call(tmp_path / "figure.png", world)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", FIGURES)
def test_path_must_name_a_png(name, world, tmp_path):
    with pytest.raises(ValueError, match="path: figures are PNG files"):
        render(name, tmp_path / "figure.pdf", world)
    assert list(tmp_path.iterdir()) == []


def test_ekf_accepts_covariances_in_place_of_sigmas(tmp_path):
    stamps, corrections, sigmas = ekf_inputs()
    covariances = np.zeros((stamps.size, 3, 3))
    covariances[:, [0, 1, 2], [0, 1, 2]] = sigmas**2
    covariances[:, 0, 1] = covariances[:, 1, 0] = 0.5 * sigmas[:, 0] * sigmas[:, 1]
    from_sigmas = plot_ekf_corrections(stamps, corrections, sigmas, tmp_path / "s.png")
    from_covariances = plot_ekf_corrections(stamps, corrections, covariances, tmp_path / "c.png")
    np.testing.assert_allclose(imread(from_sigmas), imread(from_covariances), atol=1e-6)


def test_ekf_heading_corrections_are_wrapped(tmp_path):
    stamps, corrections, sigmas = ekf_inputs()
    turned = corrections.copy()
    turned[::3, 2] += 2.0 * np.pi
    plain = plot_ekf_corrections(stamps, corrections, sigmas, tmp_path / "plain.png")
    wrapped = plot_ekf_corrections(stamps, turned, sigmas, tmp_path / "turned.png")
    np.testing.assert_allclose(imread(plain), imread(wrapped), atol=1e-6)


def pixels_of(path, colour):
    image = imread(path)[..., :3]
    return int(np.all(np.abs(image - colour) < COLOUR_TOLERANCE, axis=-1).sum())


def red_pixels(path):
    return pixels_of(path, TAB_RED)


def test_map_draws_new_polylines_in_the_palette_colour_and_confirmed_ones_not(world, tmp_path):
    confirmed = map_inputs(world, "confirmed")
    new = map_inputs(world, "new")
    as_confirmed = plot_polygonal_map(world, confirmed["map_polylines"], tmp_path / "c.png")
    as_new = plot_polygonal_map(world, new["map_polylines"], tmp_path / "n.png")
    # The legend always shows a short sample of the "new" colour; the walls' worth of new
    # polylines is much more of it than that.
    assert pixels_of(as_new, NEW_BLUE) > 20 * pixels_of(as_confirmed, NEW_BLUE)


def test_map_without_optional_layers_is_still_drawn(world, tmp_path):
    bare = plot_polygonal_map(world, [], tmp_path / "bare.png")
    assert bare.stat().st_size > MIN_PNG_BYTES
    assert np.any(imread(bare)[..., :3] < 0.95, axis=-1).mean() > MIN_INK_FRACTION


def test_lap_summary_states_totals_savings_and_stops():
    times = {policy: np.asarray(values) for policy, values in LAPS.items()}
    summary = lap_figures._lap_summary(times, {"adaptive": np.array([0, 2, 0])})
    assert summary == (
        "total: conservative 121.5 s, adaptive 103.5 s; adaptive saves 14.8%\n"
        "protective stops: adaptive 2"
    )
    slower = lap_figures._lap_summary(
        {"conservative": np.array([10.0]), "fast": np.array([11.0])}, {}
    )
    assert slower == "total: conservative 10.0 s, fast 11.0 s; fast loses 10.0%"
    assert "saves" not in lap_figures._lap_summary({"a": np.array([1.0]), "b": np.array([2.0])}, {})


def test_lap_times_accepts_more_policies_than_colours(tmp_path):
    many = {f"policy{index}": [30.0 + index, 31.0] for index in range(12)}
    assert plot_lap_times(many, tmp_path / "many.png").stat().st_size > MIN_PNG_BYTES


def test_scores_in_any_lap_order_draw_the_same_figure(tmp_path):
    forward = plot_detection_scores(SCORES, tmp_path / "forward.png")
    backward = plot_detection_scores(SCORES[::-1], tmp_path / "backward.png")
    assert forward.read_bytes() == backward.read_bytes()


def test_tangent_histograms_accept_polyline_objects(tmp_path):
    from semistatic.polyline import Polyline

    as_arrays = plot_tangent_histograms(CORNER, CORNER + 1.0, tmp_path / "arrays.png")
    as_objects = plot_tangent_histograms(
        Polyline(CORNER), Polyline(CORNER + 1.0), tmp_path / "objects.png"
    )
    assert as_arrays.read_bytes() == as_objects.read_bytes()


def test_ekf_axis_covers_every_ordinary_correction():
    _, corrections, sigmas = ekf_inputs()
    limit, outside = ekf_figure._correction_axis_limit(corrections[:, 0], sigmas[:, 0])
    assert not outside.any()
    assert limit >= np.abs(corrections[:, 0]).max()


def test_ekf_axis_flags_a_reinitialisation_jump_instead_of_stretching():
    _, corrections, sigmas = ekf_inputs()
    jumped = corrections[:, 0].copy()
    jumped[40] = 0.5  # a 50 cm jump where corrections are a few mm
    limit, outside = ekf_figure._correction_axis_limit(jumped, sigmas[:, 0])
    assert np.flatnonzero(outside).tolist() == [40]
    assert limit < 0.1


def test_ekf_figure_with_jumps_and_reinitialisations(tmp_path):
    stamps, corrections, sigmas = ekf_inputs()
    corrections[40] = [0.5, -0.3, 1.0]
    restarts = np.zeros(stamps.size, dtype=bool)
    restarts[40] = True
    flagged = plot_ekf_corrections(
        stamps, corrections, sigmas, tmp_path / "relocalised.png", reinitialized=restarts
    )
    # A re-localisation is no correction: a dotted line, no marker beyond the axis.
    assert red_pixels(flagged) == 0
    unflagged = plot_ekf_corrections(stamps, corrections, sigmas, tmp_path / "jumps.png")
    # An unexplained jump is drawn: both the markers and the legend sample are tab:red.
    assert red_pixels(unflagged) > 50


# --- The figures of a run, from a RunLog whose every number is set here ---------------

RUN_START = (0.0, 40.0)  # each lap's start (s of the run)
RUN_TICKS = 60
RUN_DT = 0.25
RUN_SPEED = 0.4  # m/s, straight along x: the speed line must read it


def run_log():
    """A two-lap pal3b RunLog (adaptive, seed 4) with stops, an infraction and map objects."""
    spec = dataclasses.replace(load_scenario("pal3b"), policy="adaptive", seed=4, laps=2,
                               moves=())
    world = scenario_world(spec)
    log = RunLog(spec=spec, world=world, robot=get_preset(spec.robot), segments=())
    for lap, start in enumerate(RUN_START, start=1):
        log.laps.append(LapLog(lap=lap, start_time=start, first_tick=len(log.stamps),
                               duration_s=RUN_TICKS * RUN_DT, completed=True, stops=lap - 1,
                               detection={"tp": 3, "fp": 0, "fn": 0, "precision": 1.0,
                                          "recall": 1.0, "f1": 1.0}))
        for tick in range(RUN_TICKS):
            pose = np.array([1.0 + RUN_SPEED * tick * RUN_DT, 0.5, 0.0])
            log.stamps.append(start + tick * RUN_DT)
            log.true_poses.append(pose)
            log.estimated_poses.append(pose + 1e-4)
    features = [  # first seen in lap 1 (two), in lap 2 (one)
        {"geometry": {"coordinates": [[0.0, 1.0], [2.0, 1.0]]},
         "properties": {"segment": "hall", "status": "confirmed", "id": ident,
                        "first_seen": seen}}
        for ident, seen in ((0, 1.0), (1, 5.0), (7, 43.5))
    ]
    log.maps_after_lap = [{"hall": {"features": features[:2]}}, {"hall": {"features": features}}]
    log.truth_after_lap = [{box.name: box.corners() for box in world.boxes}] * 2
    count = 20
    log.ekf_history = {"stamp": np.linspace(0.0, 10.0, count),
                       "correction": np.full((count, 3), 1e-4),
                       "sigma": np.full((count, 3), 1e-3),
                       "reinitialized": np.zeros(count, dtype=bool)}
    log.example_pair = (CORNER, CORNER + 0.01)
    record = SafetyRecord()
    record.protective_stops = [{"t": 45.0, "lap": 2, "speed": 0.4, "object": "person walker"},
                               {"t": 48.25, "lap": 2, "speed": 0.3, "object": "wall 1"}]
    record.infraction("near_miss", t=3.5, vehicle="robot", lap=1, where=(2.5, 0.5),
                      detail="person walker 0.1 m from the vehicle")
    log.safety_record = record
    return log


@pytest.fixture
def drawn(tmp_path, monkeypatch):
    """Write a run's figures and return them as {file name: matplotlib Figure}."""
    figures = {}
    for module in (map_figure, ekf_figure, sharing_figure, tangents_figure, lap_figures,
                   events_figure):
        real = module.write_png

        def spy(fig, path, real=real):
            figures[path.name] = fig
            return real(fig, path)

        monkeypatch.setattr(module, "write_png", spy)
    log = run_log()
    run_figures.write_figures(log, tmp_path / "figures")
    assert sorted(figures) == sorted(p.name for p in (tmp_path / "figures").iterdir())
    return log, figures


def titles(fig):
    return "\n".join([fig._suptitle.get_text() if fig._suptitle else ""]
                     + [ax.get_title() for ax in fig.axes])


def test_every_run_figure_names_the_scenario_policy_seed_and_laps(drawn):
    _, figures = drawn
    assert {"polygonal_map.png", "ekf_corrections.png", "tangent_histograms.png",
            "detection_scores.png", "events.png"} <= set(figures)
    for name, fig in figures.items():
        text = titles(fig)
        for fact in ("pal3b", "policy adaptive", "seed 4", "2 laps"):
            assert fact in text, f"{name}: {fact!r} not in its title {text!r}"


def test_people_are_drawn_on_the_map_along_their_waypoints(drawn):
    _, figures = drawn
    ax = figures["polygonal_map.png"].axes[0]
    people = load_world("pal3").enable_people("walker").active_people
    assert people  # pal3b's walker: the figure must show it
    for person in people:
        (route,) = [line for line in ax.lines if line.get_gid() == f"person:{person.name}"]
        np.testing.assert_allclose(route.get_xydata(), np.asarray(person.waypoints))
        assert any(text.get_text().startswith(person.name) for text in ax.texts)
    legend = [text.get_text() for text in ax.get_legend().get_texts()]
    assert any(label.startswith("person") for label in legend)


def test_a_map_without_people_draws_no_person(world, tmp_path, monkeypatch):
    drawn = []
    monkeypatch.setattr(map_figure, "write_png", lambda fig, path: drawn.append(fig) or path)
    plot_polygonal_map(world, [], tmp_path / "map.png")
    ax = drawn[0].axes[0]
    assert not world.active_people
    assert not [line for line in ax.lines if (line.get_gid() or "").startswith("person:")]
    assert not any("person" in t.get_text() for t in ax.get_legend().get_texts())


def markers(fig, kind):
    """Return {lap row index: x data} of the event markers of ``kind``."""
    found = {}
    for row, ax in enumerate(fig.axes):
        for line in ax.lines:
            if line.get_gid() == f"event:{kind}":
                found[row] = np.asarray(line.get_xdata(), dtype=float).tolist()
    return found


def test_events_figure_marks_the_recorded_stops_infractions_and_new_objects(drawn):
    log, figures = drawn
    fig = figures["events.png"]
    # Stops and infractions: the safety record's, at their time since their lap's start.
    assert markers(fig, "stop") == {1: [45.0 - 40.0, 48.25 - 40.0]}
    assert sum(map(len, markers(fig, "stop").values())) == len(log.safety_record.protective_stops)
    assert markers(fig, "infraction") == {0: [3.5]}
    # New objects: the map polylines first seen during each lap (two in lap 1, one in lap 2).
    assert markers(fig, "new_object") == {0: [1.0, 5.0], 1: [3.5]}


def test_events_figure_draws_the_true_speed_and_sums_up_each_lap(drawn):
    log, figures = drawn
    fig = figures["events.png"]
    for ax, lap in zip(fig.axes, log.laps, strict=True):
        (speed,) = [line for line in ax.lines if line.get_gid() == "speed"]
        np.testing.assert_allclose(speed.get_ydata(), RUN_SPEED)
        row = ax.get_title(loc="left")
        assert row.startswith(f"lap {lap.lap}: {lap.duration_s:.1f} s")
        assert f"{lap.stops} stop" in row


def test_detection_bars_carry_the_scores_and_the_counts(drawn):
    log, figures = drawn
    ax = figures["detection_scores.png"].axes[0]
    for name in ("precision", "recall", "f1"):
        heights = [bar.get_height() for bar in ax.patches if bar.get_gid() == f"score:{name}"]
        assert heights == [lap.detection[name] for lap in log.laps]
    labels = [tick.get_text() for tick in ax.get_xticklabels()]
    assert labels == [f"lap {lap.lap}\ntp 3 · fp 0 · fn 0 · from people 0" for lap in log.laps]
    # Every score is written on its bar: all-1.0 scores read as such.
    values = [text.get_text() for text in ax.texts]
    assert values.count("1.00") == 3 * len(log.laps)


def test_events_reject_an_event_of_an_unknown_kind_or_lap(tmp_path):
    with pytest.raises(ValueError, match=r"events\[0\]\.kind: must be one of"):
        plot_run_events(EVENT_LAPS, tmp_path / "e.png", events=[{"lap": 1, "t": 1.0,
                                                                  "kind": "slowdown"}])
    with pytest.raises(ValueError, match="laps: lap 1 appears twice"):
        plot_run_events([EVENT_LAPS[0]] * 2, tmp_path / "e.png")
    assert list(tmp_path.iterdir()) == []
