"""Generate a URDF for a ``UGVSpec``: collision primitives only, no meshes.

The model is what the simulator needs and no more:

- ``base_link``: the body box (visual + collision), its inertia, origin on the floor
  below the drive-axle midpoint (REP-120 ``base_link`` at the centre of rotation);
- ``left_wheel`` / ``right_wheel``: cylinders on ``continuous`` joints about +y, so a
  positive joint velocity drives the vehicle forward. The visual is the full tyre; the
  collision cylinder is a narrow disc on the tyre's mid-plane (``TYRE_CONTACT_WIDTH``).
  Load it with PyBullet's ``URDF_USE_IMPLICIT_CYLINDER`` flag: without it PyBullet
  replaces cylinders by polygonal hulls and the wheels roll like polygons;
- ``caster_N``: low-friction spheres on fixed joints, touching the floor (a ball caster
  carries load but transmits no traction);
- one link per laser mount on a fixed joint (visual only: a laser housing with a
  collision shape would intercept its own rays).

Contact friction is written into each link's ``<contact>`` block (PyBullet reads it);
PyBullet multiplies the friction of the two touching bodies, so the floor should have
lateral friction 1 for the wheel's coefficient to hold.

Examples
--------
>>> from robots.presets import PIONEER3DX
>>> text = ugv_urdf(PIONEER3DX)
>>> text.count("<link "), text.count('type="continuous"')
(5, 2)
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from robots.presets import LaserMount, UGVSpec

__all__ = [
    "CASTER_LATERAL_FRICTION",
    "LASER_LINK_MASS",
    "TYRE_CONTACT_WIDTH",
    "WHEEL_LATERAL_FRICTION",
    "laser_link_names",
    "ugv_urdf",
    "write_urdf",
]

# Rubber or polyurethane tyres on a dry industrial floor: Coulomb friction ~1.
WHEEL_LATERAL_FRICTION = 1.0
# Width of the wheel's collision cylinder. Bullet touches a cylinder lying on a plane at
# a single point on one rim; with full-width tyres the left and right contacts sit on
# different sides of their mid-planes, so equal motor torques yaw the robot while it
# accelerates. A narrow disc on the mid-plane puts both contacts where the track is
# measured. The tyres sit inside the body's outline, so walls never touch them first.
TYRE_CONTACT_WIDTH = 0.004
# A ball caster rolls freely in every direction: it carries load but no tangential force.
CASTER_LATERAL_FRICTION = 0.0
# Laser housings are folded into the body mass; their links only need a valid inertia.
LASER_LINK_MASS = 1e-3
_LASER_HOUSING_RADIUS = 0.05
_LASER_HOUSING_HEIGHT = 0.08
_HALF_PI = 1.5707963267948966


def _fmt(*values: float) -> str:
    return " ".join(f"{float(v):.12g}" for v in values)


def _origin(parent: ET.Element, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> None:
    ET.SubElement(parent, "origin", xyz=_fmt(*xyz), rpy=_fmt(*rpy))


def _inertial(link: ET.Element, mass: float, diagonal, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)):
    inertial = ET.SubElement(link, "inertial")
    _origin(inertial, xyz, rpy)
    ET.SubElement(inertial, "mass", value=_fmt(mass))
    ixx, iyy, izz = diagonal
    ET.SubElement(
        inertial, "inertia", ixx=_fmt(ixx), ixy="0", ixz="0", iyy=_fmt(iyy), iyz="0", izz=_fmt(izz)
    )


def _geometry(parent: ET.Element, kind: str, **attributes: str) -> None:
    geometry = ET.SubElement(parent, "geometry")
    ET.SubElement(geometry, kind, **attributes)


def _shape(
    link: ET.Element,
    kind: str,
    attributes: dict[str, str],
    material: str,
    *,
    collision: bool,
    xyz=(0.0, 0.0, 0.0),
    rpy=(0.0, 0.0, 0.0),
) -> None:
    visual = ET.SubElement(link, "visual")
    _origin(visual, xyz, rpy)
    _geometry(visual, kind, **attributes)
    ET.SubElement(visual, "material", name=material)
    if collision:
        element = ET.SubElement(link, "collision")
        _origin(element, xyz, rpy)
        _geometry(element, kind, **attributes)


def _contact(link: ET.Element, lateral_friction: float) -> None:
    contact = ET.SubElement(link, "contact")
    ET.SubElement(contact, "lateral_friction", value=_fmt(lateral_friction))
    ET.SubElement(contact, "rolling_friction", value="0")
    ET.SubElement(contact, "spinning_friction", value="0")


def _joint(robot: ET.Element, name: str, kind: str, child: str, xyz, rpy=(0.0, 0.0, 0.0)):
    joint = ET.SubElement(robot, "joint", name=name, type=kind)
    ET.SubElement(joint, "parent", link="base_link")
    ET.SubElement(joint, "child", link=child)
    _origin(joint, xyz, rpy)
    return joint


def laser_link_names(spec: UGVSpec) -> dict[str, LaserMount]:
    """Return the URDF link name of each distinct laser mount of ``spec``.

    A scanner that serves both roles gets one link, ``laser``; otherwise the links are
    ``safety_laser`` and ``localization_laser``.

    Examples
    --------
    >>> from robots.presets import LGV, PIONEER3DX
    >>> list(laser_link_names(PIONEER3DX)), list(laser_link_names(LGV))
    (['laser'], ['safety_laser', 'localization_laser'])
    """
    if spec.safety_laser is spec.localization_laser or spec.safety_laser == spec.localization_laser:
        return {"laser": spec.safety_laser}
    return {"safety_laser": spec.safety_laser, "localization_laser": spec.localization_laser}


def ugv_urdf(spec: UGVSpec) -> str:
    """Return the URDF text of ``spec``'s vehicle.

    Parameters
    ----------
    spec
        The vehicle description; all dimensions are taken from it.

    Returns
    -------
    str
        A complete URDF document (``<?xml ...?>`` header included).

    Examples
    --------
    >>> from robots.presets import LGV
    >>> import xml.etree.ElementTree as ET
    >>> robot = ET.fromstring(ugv_urdf(LGV).split("?>", 1)[1])
    >>> robot.get("name"), [j.get("name") for j in robot.iter("joint")][:2]
    ('lgv', ['left_wheel_joint', 'right_wheel_joint'])
    """
    robot = ET.Element("robot", name=spec.name)
    for name, rgba in (
        ("body", (0.75, 0.12, 0.10, 1.0)),
        ("tyre", (0.08, 0.08, 0.08, 1.0)),
        ("caster", (0.55, 0.55, 0.55, 1.0)),
        ("laser", (0.95, 0.80, 0.10, 1.0)),
    ):
        material = ET.SubElement(robot, "material", name=name)
        ET.SubElement(material, "color", rgba=_fmt(*rgba))

    base = ET.SubElement(robot, "link", name="base_link")
    box_height = spec.body_height - spec.ground_clearance
    centre = (spec.body_x_offset, 0.0, spec.ground_clearance + 0.5 * box_height)
    lx, ly, lz = spec.body_length, spec.body_width, box_height
    m = spec.body_mass
    _inertial(
        base,
        m,
        (m * (ly**2 + lz**2) / 12.0, m * (lx**2 + lz**2) / 12.0, m * (lx**2 + ly**2) / 12.0),
        xyz=centre,
    )
    _shape(base, "box", {"size": _fmt(lx, ly, lz)}, "body", collision=True, xyz=centre)

    r, w, m = spec.wheel_radius, spec.wheel_width, spec.wheel_mass
    axial = 0.5 * m * r**2
    transverse = m * (3.0 * r**2 + w**2) / 12.0
    for side, sign in (("left", 1.0), ("right", -1.0)):
        link_name = f"{side}_wheel"
        wheel = ET.SubElement(robot, "link", name=link_name)
        # URDF cylinders lie along z; rolling about x by pi/2 puts the axle along y.
        rpy = (_HALF_PI, 0.0, 0.0)
        _inertial(wheel, m, (transverse, transverse, axial), rpy=rpy)
        _shape(
            wheel,
            "cylinder",
            {"radius": _fmt(r), "length": _fmt(w)},
            "tyre",
            collision=False,
            rpy=rpy,
        )
        collision = ET.SubElement(wheel, "collision")
        _origin(collision, rpy=rpy)
        _geometry(collision, "cylinder", radius=_fmt(r), length=_fmt(min(w, TYRE_CONTACT_WIDTH)))
        _contact(wheel, WHEEL_LATERAL_FRICTION)
        joint = _joint(
            robot,
            f"{link_name}_joint",
            "continuous",
            link_name,
            xyz=(0.0, sign * 0.5 * spec.wheel_separation, r),
        )
        ET.SubElement(joint, "axis", xyz="0 1 0")
        ET.SubElement(joint, "dynamics", damping="0", friction="0")

    rc, mc = spec.caster_radius, spec.caster_mass
    for index, (cx, cy) in enumerate(spec.caster_positions):
        link_name = f"caster_{index}"
        caster = ET.SubElement(robot, "link", name=link_name)
        _inertial(caster, mc, (0.4 * mc * rc**2,) * 3)
        _shape(caster, "sphere", {"radius": _fmt(rc)}, "caster", collision=True)
        _contact(caster, CASTER_LATERAL_FRICTION)
        _joint(robot, f"{link_name}_joint", "fixed", link_name, xyz=(cx, cy, rc))

    tiny = LASER_LINK_MASS * _LASER_HOUSING_RADIUS**2
    for link_name, mount in laser_link_names(spec).items():
        laser = ET.SubElement(robot, "link", name=link_name)
        _inertial(laser, LASER_LINK_MASS, (tiny, tiny, tiny))
        _shape(
            laser,
            "cylinder",
            {"radius": _fmt(_LASER_HOUSING_RADIUS), "length": _fmt(_LASER_HOUSING_HEIGHT)},
            "laser",
            collision=False,
        )
        _joint(
            robot,
            f"{link_name}_joint",
            "fixed",
            link_name,
            xyz=(mount.x, mount.y, mount.z),
            rpy=(0.0, 0.0, mount.yaw),
        )

    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def write_urdf(spec: UGVSpec, directory: str | Path) -> Path:
    """Write ``spec``'s URDF to ``directory/<spec.name>.urdf`` and return the path.

    The directory is created if needed; an existing file of that name is replaced.

    Examples
    --------
    >>> import tempfile
    >>> from robots.presets import PIONEER3DX
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_urdf(PIONEER3DX, tmp)
    ...     path.name, path.read_text().startswith("<?xml")
    ('pioneer3dx.urdf', True)
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{spec.name}.urdf"
    path.write_text(ugv_urdf(spec))
    return path
