"""Everything that touches PyBullet: client, world builder, UGV body, lasers, ground truth."""

from sim.client import SimClient
from sim.contacts import Contact, ContactMonitor
from sim.encoders import WheelEncoders
from sim.ground_truth import box_outlines, people_positions, visible_outlines
from sim.laser import RaycastLaser, exclude_from_lasers
from sim.people import People
from sim.ugv import SimUGV, add_floor
from sim.world_builder import SimWorld

__all__ = [
    "Contact",
    "ContactMonitor",
    "People",
    "RaycastLaser",
    "SimClient",
    "SimUGV",
    "SimWorld",
    "WheelEncoders",
    "add_floor",
    "box_outlines",
    "exclude_from_lasers",
    "people_positions",
    "visible_outlines",
]
