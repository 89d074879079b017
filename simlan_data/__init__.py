"""simlan_data: record-and-replay data and evaluation platform for multi-camera warehouse robotics.

A PyBullet twin of SIMLAN's warehouse and its calibrated ceiling cameras (Volvo GPSS), recorded as
ROS 2 bags (MCAP storage) and replayed through the same algorithms to compute V&V metrics.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
