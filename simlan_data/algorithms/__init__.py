"""The GPSS algorithms: markers, localization, planning, following, coordination, safety, bird's-eye."""

from __future__ import annotations

import lazy_loader

# Each public name loads its submodule on first use (lazy_loader, PEP 562): importing the
# subpackage stays light (no simulator, no torch until a name that needs them is used).
__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "aruco_localizer": ["ArucoLocalizer"],
        "foreground_localizer": ["ForegroundConfig", "ForegroundLocalizer"],
        "birdseye": ["BirdseyeStitcher", "CanvasSpec"],
        "birdseye_stitcher": ["GpssStitcher", "GpssStitcherConfig"],
        "gpss_coordinator": ["GpssCoordinator", "GpssCoordinatorConfig"],
        "localization": ["LocalizerParams", "PoseEstimate"],
        "registry": ["ENTRY_POINT_GROUP", "AlgorithmSpec", "Guarded", "names", "resolve"],
        "roles": [
            "ROLES",
            "CameraFrame",
            "Coordinator",
            "CoordinatorContext",
            "Localizer",
            "LocalizerContext",
            "PoseMapper",
            "PosemapContext",
            "SafetyContext",
            "SafetyMonitor",
            "SearchingLocalizer",
            "Stitcher",
            "StitcherContext",
        ],
        "trained_posemap": ["TrainedPoseMapper"],
        "birdseye_simlan": ["SimlanBirdseye"],
        "coordinator": ["Decision", "Intent"],
        "dryrun": ["DryRunResult", "dry_run"],
        "follower": ["FollowerParams", "PathFollower", "PursuitParams", "WaypointFollower"],
        "markers": ["Detection", "MarkerDetector", "MarkerMount", "MarkerObservation"],
        "navigation": ["NavigationStatus", "Navigator"],
        "occupancy": ["OccupancyGrid", "grid_from_nav2_map", "grid_from_world"],
        "people": ["PeopleParams", "PersonDetection", "PersonDetector", "PersonTracker"],
        "planner": ["GridPlanner", "Plan", "PlanningError"],
    },
)
