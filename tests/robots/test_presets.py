"""UGV presets, their validation, the wheel kinematics and the generated URDF."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import shapely

from robots.lasers import LMS100, S300
from robots.presets import LGV, PIONEER3DX, PRESETS, LaserMount, UGVSpec, get_preset
from robots.urdf import (
    CASTER_LATERAL_FRICTION,
    LASER_LINK_MASS,
    TYRE_CONTACT_WIDTH,
    WHEEL_LATERAL_FRICTION,
    laser_link_names,
    ugv_urdf,
    write_urdf,
)
from tests.spec_errors import raises_spec_error

ALL_PRESETS = sorted(PRESETS.values(), key=lambda spec: spec.name)


def test_registry_names_and_lookup():
    assert set(PRESETS) == {"pioneer3dx", "lgv"}
    assert get_preset("pioneer3dx") is PIONEER3DX
    assert get_preset("  LGV ") is LGV


def test_unknown_preset_suggests_the_close_name():
    with pytest.raises(KeyError, match="did you mean 'pioneer3dx'"):
        get_preset("pioner3dx")
    with pytest.raises(KeyError, match="known: lgv, pioneer3dx"):
        get_preset("forklift")


def test_pioneer_matches_the_data_sheet():
    spec = PIONEER3DX
    assert (spec.body_length, spec.body_width, spec.body_height) == (0.455, 0.381, 0.237)
    assert spec.wheel_radius * 2 == pytest.approx(0.195)
    assert spec.total_mass == pytest.approx(9.0)
    assert spec.encoder_ticks_per_rev == 19150
    assert spec.max_speed == pytest.approx(1.2)
    assert len(spec.caster_positions) == 1
    assert spec.caster_positions[0][0] < 0.0  # rear caster
    # One LMS100 serves both roles: the very same mount object.
    assert spec.safety_laser is spec.localization_laser
    assert spec.safety_laser.laser is LMS100


def test_lgv_has_a_low_safety_laser_and_a_high_localization_laser():
    assert LGV.safety_laser.laser is S300
    assert LGV.localization_laser.laser is LMS100
    assert LGV.safety_laser.z == pytest.approx(0.15)
    assert LGV.localization_laser.z == pytest.approx(2.0)
    assert LGV.safety_laser.x > 0.5 * LGV.body_length - 0.05  # at the front
    assert LGV.total_mass > 10 * PIONEER3DX.total_mass
    assert LGV.body_length == 1.2
    assert LGV.body_width == 0.8


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_footprint_covers_body_and_sensors(spec):
    footprint = shapely.Polygon(spec.footprint)
    assert footprint.is_valid
    assert footprint.exterior.is_ccw
    for mount in (spec.safety_laser, spec.localization_laser):
        assert footprint.covers(shapely.Point(mount.x, mount.y))
    body = shapely.box(
        spec.body_x_offset - spec.body_length / 2,
        -spec.body_width / 2,
        spec.body_x_offset + spec.body_length / 2,
        spec.body_width / 2,
    )
    assert footprint.buffer(1e-9).covers(body)
    # The tyres stay inside the body outline: walls meet the body first.
    assert spec.wheel_separation / 2 + spec.wheel_width / 2 <= spec.body_width / 2


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_wheel_speeds_and_twist_are_inverse(spec):
    rng = np.random.default_rng(3)
    v = rng.uniform(-1.5, 1.5, 50)
    omega = rng.uniform(-2.0, 2.0, 50)
    left, right = spec.wheel_speeds(v, omega)
    assert left.shape == (50,)
    v_back, omega_back = spec.twist_from_wheel_speeds(left, right)
    np.testing.assert_allclose(v_back, v, atol=1e-12)
    np.testing.assert_allclose(omega_back, omega, atol=1e-12)


def test_wheel_speeds_of_simple_motions():
    spec = PIONEER3DX
    left, right = spec.wheel_speeds(spec.max_speed, 0.0)
    assert left == pytest.approx(spec.max_wheel_speed)
    assert right == pytest.approx(spec.max_wheel_speed)
    left, right = spec.wheel_speeds(0.0, 1.0)  # turn left on the spot: right wheel forward
    assert right == pytest.approx(-left)
    assert right == pytest.approx(0.5 * spec.wheel_separation / spec.wheel_radius)
    assert isinstance(left, float)
    assert spec.max_omega == pytest.approx(2 * spec.max_speed / spec.wheel_separation)
    assert spec.metres_per_tick == pytest.approx(2 * math.pi * 0.0975 / 19150)


@pytest.mark.parametrize(
    ("changes", "key", "message"),
    [
        ({"wheel_radius": 0.0}, "wheel_radius", r"must be > 0.0 and <= 2.0, got 0.0 \(metres"),
        ({"wheel_radius": 5.0}, "wheel_radius", r"must be > 0.0 and <= 2.0, got 5.0"),
        ({"body_mass": float("nan")}, "body_mass", "must be a finite number, got nan"),
        ({"body_mass": 1e6}, "body_mass", r"<= 50000.0, got 1000000.0 \(kg\)"),
        ({"body_length": 30.0}, "body_length", "<= 20.0, got 30.0"),
        ({"wheel_separation": 0.04}, "wheel_separation", r"must exceed wheel_width \(0.047 m\)"),
        ({"encoder_slip_sigma": -0.1}, "encoder_slip_sigma", ">= 0.0 and <= 1.0, got -0.1"),
        ({"encoder_ticks_per_rev": 0}, "encoder_ticks_per_rev", ">= 1 .*, got 0"),
        ({"encoder_ticks_per_rev": 19150.5}, "encoder_ticks_per_rev", "expected an integer"),
        ({"encoder_ticks_per_rev": True}, "encoder_ticks_per_rev", "expected an integer"),
        ({"ground_clearance": 0.3}, "ground_clearance", r"must be < body_height \(0.237 m\)"),
        ({"caster_positions": ()}, "caster_positions", "at least one"),
        ({"caster_positions": ((0.0, 0.0, 0.0),)}, "caster_positions[0]", "list of 2 numbers"),
        ({"caster_positions": ((-25.0, 0.0),)}, "caster_positions[0]", "every value must be"),
        ({"caster_positions": ((0.2, 0.0),)}, "caster_positions", "centre of mass .* strictly"),
        ({"footprint": ((0, 0), (1, 0))}, "footprint", "at least 3"),
        ({"footprint": ((0, 0), (0, 1), (1, 0))}, "footprint", "counter-clockwise"),
        ({"footprint": ((0, 0), (1, float("inf")), (0, 1))}, "footprint[1][1]", "finite"),
        ({"name": "Pioneer"}, "name", "lower-case"),
        ({"max_wheel_torque": -1.0}, "max_wheel_torque", r"> 0.0 .*, got -1.0 \(N m"),
        ({"max_wheel_speed": 1000.0}, "max_wheel_speed", "<= 500.0, got 1000.0"),
    ],
)
def test_spec_built_in_code_names_the_key(changes, key, message):
    with raises_spec_error(key, message):
        PIONEER3DX.replace(**changes)


def test_spec_validation_rejects_a_laser_where_a_mount_belongs():
    with pytest.raises(TypeError, match="safety_laser must be a LaserMount"):
        PIONEER3DX.replace(safety_laser=LMS100)


def test_spec_fields_are_converted_to_plain_python_numbers():
    spec = PIONEER3DX.replace(
        wheel_radius=np.float32(0.1), encoder_ticks_per_rev=np.int64(1000), body_mass=8
    )
    assert type(spec.wheel_radius) is float
    assert type(spec.body_mass) is float
    assert type(spec.encoder_ticks_per_rev) is int
    assert spec.caster_positions == ((-0.2, 0.0),)


@pytest.mark.parametrize(
    ("kwargs", "key", "message"),
    [
        ({"z": 0.0}, "z", r"must be > 0.0 and <= 10.0, got 0.0 \(metres: height"),
        ({"z": 0.3, "yaw": 4.0}, "yaw", r"> -3.14.* and <= 3.14.*, got 4.0 \(wrap it"),
        ({"z": 0.3, "yaw": -math.pi}, "yaw", "> -3.14"),
        ({"z": 0.3, "x": float("inf")}, "x", "must be a finite number, got inf"),
        ({"z": 0.3, "y": 21.0}, "y", "<= 20.0, got 21.0"),
    ],
)
def test_laser_mount_validation(kwargs, key, message):
    with raises_spec_error(key, message):
        LaserMount(LMS100, **{"x": 0.0, "y": 0.0, **kwargs})


def test_laser_mount_requires_a_laser_spec():
    with pytest.raises(TypeError, match="LaserSpec"):
        LaserMount("LMS100", x=0.0, y=0.0, z=0.3)


def test_specs_are_frozen():
    with pytest.raises(AttributeError):
        PIONEER3DX.wheel_radius = 0.1  # type: ignore[misc]
    assert isinstance(PIONEER3DX, UGVSpec)


# --- URDF -------------------------------------------------------------------------------


def _parse(spec):
    return ET.fromstring(ugv_urdf(spec).split("?>", 1)[1])


def _floats(text):
    return [float(v) for v in text.split()]


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_urdf_wheels_are_continuous_joints_on_the_axle(spec):
    robot = _parse(spec)
    joints = {j.get("name"): j for j in robot.iter("joint")}
    for side, sign in (("left", 1.0), ("right", -1.0)):
        joint = joints[f"{side}_wheel_joint"]
        assert joint.get("type") == "continuous"
        assert _floats(joint.find("axis").get("xyz")) == [0.0, 1.0, 0.0]
        xyz = _floats(joint.find("origin").get("xyz"))
        assert xyz == pytest.approx([0.0, sign * spec.wheel_separation / 2, spec.wheel_radius])
        link = next(lk for lk in robot.iter("link") if lk.get("name") == f"{side}_wheel")
        cylinder = link.find("collision/geometry/cylinder")
        assert float(cylinder.get("radius")) == spec.wheel_radius
        assert float(cylinder.get("length")) == min(spec.wheel_width, TYRE_CONTACT_WIDTH)
        visual = link.find("visual/geometry/cylinder")
        assert float(visual.get("length")) == spec.wheel_width
        friction = float(link.find("contact/lateral_friction").get("value"))
        assert friction == WHEEL_LATERAL_FRICTION


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_urdf_casters_touch_the_floor_and_slide(spec):
    robot = _parse(spec)
    joints = {j.get("name"): j for j in robot.iter("joint")}
    links = {lk.get("name"): lk for lk in robot.iter("link")}
    for index, (cx, cy) in enumerate(spec.caster_positions):
        joint = joints[f"caster_{index}_joint"]
        assert joint.get("type") == "fixed"
        x, y, z = _floats(joint.find("origin").get("xyz"))
        radius = float(links[f"caster_{index}"].find("collision/geometry/sphere").get("radius"))
        assert (x, y) == (cx, cy)
        assert z - radius == pytest.approx(0.0)  # the sphere's bottom is on the floor
        friction = float(links[f"caster_{index}"].find("contact/lateral_friction").get("value"))
        assert friction == CASTER_LATERAL_FRICTION


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_urdf_laser_links_sit_at_the_mounts_without_collision(spec):
    robot = _parse(spec)
    joints = {j.get("name"): j for j in robot.iter("joint")}
    links = {lk.get("name"): lk for lk in robot.iter("link")}
    for name, mount in laser_link_names(spec).items():
        joint = joints[f"{name}_joint"]
        assert joint.get("type") == "fixed"
        assert _floats(joint.find("origin").get("xyz")) == pytest.approx(
            [mount.x, mount.y, mount.z]
        )
        assert _floats(joint.find("origin").get("rpy"))[2] == pytest.approx(mount.yaw)
        assert links[name].find("collision") is None


@pytest.mark.parametrize("spec", ALL_PRESETS, ids=lambda s: s.name)
def test_urdf_masses_add_up(spec):
    robot = _parse(spec)
    masses = [float(m.get("value")) for m in robot.iter("mass")]
    lasers = len(laser_link_names(spec)) * LASER_LINK_MASS
    assert sum(masses) == pytest.approx(spec.total_mass + lasers)
    for inertia in robot.iter("inertia"):
        assert all(float(inertia.get(k)) > 0 for k in ("ixx", "iyy", "izz"))


def test_urdf_body_box_spans_clearance_to_top():
    robot = _parse(PIONEER3DX)
    base = next(lk for lk in robot.iter("link") if lk.get("name") == "base_link")
    size = _floats(base.find("collision/geometry/box").get("size"))
    centre = _floats(base.find("collision/origin").get("xyz"))
    assert centre[2] - size[2] / 2 == pytest.approx(PIONEER3DX.ground_clearance)
    assert centre[2] + size[2] / 2 == pytest.approx(PIONEER3DX.body_height)
    assert centre[0] == pytest.approx(PIONEER3DX.body_x_offset)


def test_laser_link_names_split_distinct_mounts():
    assert list(laser_link_names(PIONEER3DX)) == ["laser"]
    assert list(laser_link_names(LGV)) == ["safety_laser", "localization_laser"]


def test_write_urdf_creates_the_directory(tmp_path):
    path = write_urdf(LGV, tmp_path / "nested" / "dir")
    assert path == tmp_path / "nested" / "dir" / "lgv.urdf"
    assert path.read_text() == ugv_urdf(LGV)
