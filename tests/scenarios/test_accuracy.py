"""Map accuracy of every paper scenario against the paper's bounds (``pytest -m accuracy``).

Each scenario runs its full 5 laps. The bounds are the paper's and the issue's (Table 1
means under 10 cm, detection F1 >= 0.9, no collision, no object made of a person). Silent
drifts are caught statistically: ``make accuracy`` compares a ten-seed campaign with the
stored baseline (``tests/scenarios/accuracy_baseline``) through ``semistatic compare``.
"""

import pytest
import shapely

from scenarios.bench.runner import run_scenario
from scenarios.results.outputs import summarize
from scenarios.spec.layout import lap_worlds
from scenarios.spec.load import load_scenario, paper_scenarios

PAPER_BOUND_CM = 10.0


@pytest.fixture(scope="module", params=paper_scenarios())
def runs(request):
    spec = load_scenario(request.param)
    log = run_scenario(spec)
    return request.param, summarize(log), spec, log


@pytest.fixture
def metrics(runs):
    return runs[:2]


@pytest.mark.accuracy
def test_meets_the_papers_bound_and_detects_boxes_safely(metrics):
    _, result = metrics
    assert result["table1_cm"]["mean"]["max"] < PAPER_BOUND_CM
    assert result["detection"]["f1"] >= 0.9
    assert result["detection"]["false_objects_from_people"] == 0
    assert result["safety"]["collisions"] == 0
    assert result["safety"]["laps_completed"] == result["laps"]


MOVED_BOX = ("sim1", "carton_aisle")
# The box's map polyline must follow its visible outline to this (m) after lap 5, and no
# part of it may lie deeper inside the box than this (m): no edge across the footprint.
OUTLINE_HAUSDORFF_M = 0.05
INSIDE_DEPTH_M = 0.03


@pytest.mark.accuracy
def test_a_moved_box_map_follows_its_new_outline(runs):
    name, _, spec, log = runs
    if name != MOVED_BOX[0]:
        pytest.skip(f"the moved-box check runs on {MOVED_BOX[0]}")
    box = next(b for b in lap_worlds(spec)[-1].boxes if b.name == MOVED_BOX[1])
    footprint = shapely.Polygon(box.corners())
    lines = [
        shapely.LineString(feature["geometry"]["coordinates"])
        for collection in log.maps_after_lap[-1].values()
        for feature in collection["features"]
        if feature["geometry"] is not None
    ]
    near = [line for line in lines if line.distance(footprint) < OUTLINE_HAUSDORFF_M]
    assert len(near) == 1
    # its visible outline: the faces whose middles the polyline passes near
    corners = box.corners()
    faces = [shapely.LineString([corners[k], corners[(k + 1) % len(corners)]])
             for k in range(len(corners))]
    visible = [face for face in faces
               if face.interpolate(0.5, normalized=True).distance(near[0]) < OUTLINE_HAUSDORFF_M]
    outline = shapely.MultiLineString(visible)
    assert shapely.hausdorff_distance(near[0], outline) < OUTLINE_HAUSDORFF_M
    assert near[0].intersection(footprint.buffer(-INSIDE_DEPTH_M)).length == 0.0
