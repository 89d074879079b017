"""The built-in localizer (``aruco``), registered like any plug-in: ArUco markers, fused, EKF.

It implements the localizer protocol (:class:`~simlan_data.algorithms.roles.Localizer`) and the
optional searching protocol (:class:`~simlan_data.algorithms.roles.SearchingLocalizer`) with which
the live loop and the replay search images on worker threads while the next cameras render or
are read. Both paths make the same calls in the same order, so they give the same estimates.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar

from simlan_data.algorithms.localization import Localizer, LocalizerParams
from simlan_data.algorithms.roles import CameraFrame, LocalizerContext


class ArucoLocalizer(Localizer):
    """Marker poses from every camera that sees them, fused per frame set, filtered by an EKF."""

    role: ClassVar[str] = "localizer"
    config_class: ClassVar[type] = LocalizerParams

    def __init__(self, config: LocalizerParams, context: LocalizerContext) -> None:
        super().__init__(dict(context.cameras), list(context.robots), config)

    def observe(self, t_ns: int, frames: Mapping[str, CameraFrame]) -> None:
        """Search every planned image of one camera tick (in camera order), then fuse."""
        ids = [cid for cid in self.cameras if cid in frames]
        for cid, plan in zip(ids, self.search_plans(t_ns, ids)):
            if plan:
                self.observe_search(t_ns, cid, plan, self.detect(cid, plan, jpeg=frames[cid].jpeg))
        self.close_frame(t_ns)
