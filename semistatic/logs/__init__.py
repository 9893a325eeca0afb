"""Real laser logs in and out: CARMEN logs, ROS 1 / ROS 2 bags, extraction quality.

Examples
--------
>>> from semistatic.logs import read_carmen, LogFormatError
>>> issubclass(LogFormatError, ValueError)
True
"""

from semistatic.logs.carmen import LogFormatError, ReadStats, infer_no_return, read_carmen
from semistatic.logs.quality import (
    ExtractionQuality,
    QualitySummary,
    extraction_quality,
    inlier_mask,
    summarize_quality,
)
from semistatic.logs.rosbag import BagError, BagFrame, BagStats, read_bag, write_ros2_bag

__all__ = [
    "BagError",
    "BagFrame",
    "BagStats",
    "ExtractionQuality",
    "LogFormatError",
    "QualitySummary",
    "ReadStats",
    "extraction_quality",
    "infer_no_return",
    "inlier_mask",
    "read_bag",
    "read_carmen",
    "summarize_quality",
    "write_ros2_bag",
]
