"""semistatic: semi-static object detection with polygonal local maps.

The paper's contribution as a pure numpy/scipy library that runs on any 2D laser scan,
simulated or real. No simulator imports here.
"""

from semistatic.params import MapperParams
from semistatic.types import Scan

__all__ = ["MapperParams", "Scan"]
