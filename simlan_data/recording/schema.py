"""The recording contract: every topic name, message type and frame name, in one place.

Standard ROS 2 types wherever one fits; custom types live in the ``simlan_msgs`` package of .msg
files shipped in ``simlan_data/recording/msg`` and embedded in each bag's MCAP schemas, so any
MCAP/ROS 2 reader can decode them without ROS installed.

Frames (SIMLAN's): ``map`` is the world, static at the origin; ``camera_<id>_optical_frame`` is a
camera (OpenCV axes: x right, y down, z forward); ``<ns>/base_link`` is an agent as its
localization sees it (``map -> <ns>/odom`` on /tf_static, ``<ns>/odom -> <ns>/base_link`` on /tf);
``ground_truth/<ns>/base_link`` is where the agent truly is (``map ->`` it on
``/ground_truth/poses``, never on ``/tf``). Every frame has one parent (REP 105), so viewers that
read every TFMessage topic (Rerun, Foxglove) show both the estimate and the truth.

Time: log times and header stamps are bag time, the simulated clock plus the recording's epoch
(``timebase.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from simlan_data.constants import MSG_DIR

MAP_FRAME = "map"

# ---------------------------------------------------------------------------------- msg types
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
TF_TYPE = "tf2_msgs/msg/TFMessage"
STRING_TYPE = "std_msgs/msg/String"
IMAGE_TYPE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE_TYPE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
TWIST_STAMPED_TYPE = "geometry_msgs/msg/TwistStamped"
PATH_TYPE = "nav_msgs/msg/Path"
RUN_INFO_TYPE = "simlan_msgs/msg/RunInfo"
SEMANTIC_LABELS_TYPE = "simlan_msgs/msg/SemanticLabels"
COLLISION_STATE_TYPE = "simlan_msgs/msg/CollisionState"
MARKER_DETECTIONS_TYPE = "simlan_msgs/msg/MarkerDetections"
NAVIGATION_STATUS_TYPE = "simlan_msgs/msg/NavigationStatus"
LOCALIZATION_STATUS_TYPE = "simlan_msgs/msg/LocalizationStatus"
POSE_COV_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE_STAMPED_TYPE = "geometry_msgs/msg/PoseStamped"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
POSE_LANDMARKS_TYPE = "simlan_msgs/msg/PoseLandmarks"
POSE_ARRAY_TYPE = "geometry_msgs/msg/PoseArray"
MARKER_ARRAY_TYPE = "visualization_msgs/msg/MarkerArray"
SAFETY_EVENT_TYPE = "simlan_msgs/msg/SafetyEvent"
SAFETY_STATE_TYPE = "simlan_msgs/msg/SafetyState"
CAMERA_EFFECTS_TYPE = "simlan_msgs/msg/CameraEffects"
# rosbags' typestores carry no vision_msgs, and its Detection2D has no visible / amodal pair,
# visible fraction or truncation: the instance ground truth has its own types
INSTANCE_TABLE_TYPE = "simlan_msgs/msg/InstanceTable"
INSTANCE_BOXES_2D_TYPE = "simlan_msgs/msg/InstanceBoxes2D"
INSTANCE_BOXES_3D_TYPE = "simlan_msgs/msg/InstanceBoxes3D"
INSTANCE_KEYPOINTS_TYPE = "simlan_msgs/msg/InstanceKeypoints"
# the same ground truth in standard types, for ROS tools and viewers (vision_msgs 4.x, Jazzy's)
DETECTION_2D_ARRAY_TYPE = "vision_msgs/msg/Detection2DArray"
STANDARD_MSG_DIR = Path(__file__).parent / "ros_types"  # standard types rosbags' typestore lacks

# ------------------------------------------------------------------------------------- topics
CLOCK = "/clock"
TF = "/tf"
TF_STATIC = "/tf_static"
GROUND_TRUTH_POSES = "/ground_truth/poses"
CONFIG = "/simlan/config"
RUN_INFO = "/simlan/run_info"
SEMANTIC_LABELS = "/simlan/semantic_labels"
RANDOMIZATION = "/simlan/randomization"
BIRDSEYE_IMAGE = "/birdseye/image"
SAFETY_EVENTS = "/safety/events"
SAFETY_ZONES = "/safety/zones"
PEOPLE_DETECTIONS = "/people/detections"
INSTANCES = "/ground_truth/instances"
INSTANCE_BOXES_3D = "/ground_truth/boxes"
INSTANCE_BOX_MARKERS = "/ground_truth/boxes/markers"
POSEMAP_SOURCE_IMAGE = "/posemap/source/image_raw/compressed"
POSEMAP_SOURCE_LANDMARKS = "/posemap/source/pose_landmarks"
POSEMAP_SOURCE_FRAME = "posemap_source"  # the source's camera: not one of the twin's
INSTANCE_PNG_FORMAT = "mono16; png compressed mono16"  # instance ids, 16-bit PNG (image_transport's form)


@dataclass(frozen=True)
class Topic:
    """A topic name with its message type and a one-line description for the README."""

    name: str
    msgtype: str
    description: str


def camera_frame(camera_id: str | int) -> str:
    return f"camera_{camera_id}_optical_frame"


def base_link_frame(namespace: str) -> str:
    return f"{namespace}/base_link"


def odom_frame(namespace: str) -> str:
    return f"{namespace}/odom"


GROUND_TRUTH_FRAME_PREFIX = "ground_truth/"


def ground_truth_frame(namespace: str) -> str:
    """The frame ``/ground_truth/poses`` places an agent at: ``ground_truth/<ns>/base_link``.

    Not ``<ns>/base_link``: /tf already gives that frame a parent (``<ns>/odom``, the estimate), and
    a frame has one parent (REP 105). Named like the topic, so a viewer's frame list groups the
    ground truth apart from the estimates.
    """
    return GROUND_TRUTH_FRAME_PREFIX + base_link_frame(namespace)


def ground_truth_namespace(child_frame_id: str) -> str:
    """The agent namespace of a child frame of ``/ground_truth/poses``: ``ground_truth/<ns>/base_link``,
    or ``<ns>/base_link`` as recordings before the ground-truth frames named it (both read alike)."""
    return child_frame_id.removeprefix(GROUND_TRUTH_FRAME_PREFIX).split("/")[0]


def camera_topics(
    camera_id: str | int, *, rgb: str, depth: str | None, semantic: str | None
) -> dict[str, Topic]:
    """Topics of one camera for the given encodings (``raw`` or a compressed format).

    Keys: ``rgb``, ``camera_info``, and ``depth`` / ``semantic`` when those streams are on (the
    ``instance`` stream's topics: :func:`instance_topics`).
    """
    base = f"/camera_{camera_id}"
    out = {
        "rgb": Topic(f"{base}/image_raw", IMAGE_TYPE, "colour image, rgb8, distorted like the real camera")
        if rgb == "raw"
        else Topic(
            f"{base}/image_raw/compressed",
            COMPRESSED_IMAGE_TYPE,
            f"colour image, {rgb}, distorted like the real camera",
        ),
        "camera_info": Topic(
            f"{base}/camera_info", CAMERA_INFO_TYPE, "K, D (plumb_bob), image size, at the image rate"
        ),
    }
    if depth is not None:
        out["depth"] = (
            Topic(
                f"{base}/depth/image_raw/compressedDepth",
                COMPRESSED_IMAGE_TYPE,
                "z-depth, 16UC1 millimetres in PNG (compressed_depth_image_transport), 0 = no return",
            )
            if depth == "png"
            else Topic(
                f"{base}/depth/image_raw",
                IMAGE_TYPE,
                "z-depth, 32FC1 metres (REP 118), NaN = no return"
                if depth == "raw"
                else "z-depth, 16UC1 millimetres (REP 118), 0 = no return",
            )
        )
    out["pose_landmarks"] = Topic(
        f"{base}/pose_landmarks",
        POSE_LANDMARKS_TYPE,
        "33 MediaPipe-style body landmarks of the person in the image (posemap.landmarks_rate_hz, or the drive's input)",
    )
    out["effects"] = Topic(
        f"{base}/effects",
        CAMERA_EFFECTS_TYPE,
        "what the camera stage did to each frame: true exposure time, stamp written, lost or not, noise field, exposure, gain, true pose (runs with sensors other than ideal)",
    )
    out["detections"] = Topic(
        f"{base}/marker_detections",
        MARKER_DETECTIONS_TYPE,
        "ArUco markers the localizer found in the image (when it searched it)",
    )
    if semantic is not None:
        out["semantic"] = (
            Topic(
                f"{base}/semantic/image_raw",
                IMAGE_TYPE,
                "semantic class ids, mono8 (see /simlan/semantic_labels)",
            )
            if semantic == "raw"
            else Topic(
                f"{base}/semantic/image_raw/compressed",
                COMPRESSED_IMAGE_TYPE,
                "semantic class ids as a palette PNG: pixel values = ids, palette = class colours "
                "(names on /simlan/semantic_labels); OpenCV/image_transport decode it to rgb8 colours",
            )
        )
    return out


def instance_topics(camera_id: str | int) -> dict[str, Topic]:
    """Topics of one camera's ``instance`` stream (issue 25): keys ``instance``, ``boxes_2d`` and
    ``keypoints`` (recorded only in scenes with people)."""
    base = f"/camera_{camera_id}"
    return {
        "instance": Topic(
            f"{base}/instances/image_raw/compressed",
            COMPRESSED_IMAGE_TYPE,
            "instance ids (track ids), 16-bit PNG (mono16), 0 = no instance (see /ground_truth/instances), with every colour image",
        ),
        "boxes_2d": Topic(
            f"{base}/instances/boxes",
            INSTANCE_BOXES_2D_TYPE,
            "per instance in the image: visible box (mask), amodal box (3D box projected), visible fraction, truncation",
        ),
        "detections": Topic(
            f"{base}/instances/detections",
            DETECTION_2D_ARRAY_TYPE,
            "the visible boxes as vision_msgs detections: id = track id, class_id = class name, score 1",
        ),
        "keypoints": Topic(
            f"{base}/instances/keypoints",
            INSTANCE_KEYPOINTS_TYPE,
            "per person instance: 33 body landmarks (MediaPipe order) in pixels, COCO visibility 0/1/2 (scenes with people)",
        ),
    }


def agent_topics(namespace: str) -> dict[str, Topic]:
    """Topics of one agent."""
    return {
        "cmd_vel": Topic(
            f"/{namespace}/cmd_vel",
            TWIST_STAMPED_TYPE,
            "velocity command applied to the robot, base_link frame",
        ),
        "collision": Topic(
            f"/{namespace}/collision",
            COLLISION_STATE_TYPE,
            "collision sensor: contacts with anything but the floor",
        ),
        "plan": Topic(
            f"/{namespace}/plan", PATH_TYPE, "planned path to the current goal (map frame), on every new plan"
        ),
        "goal": Topic(
            f"/{namespace}/goal",
            POSE_STAMPED_TYPE,
            "the goal the robot is heading for (map frame), on change",
        ),
        "pose_estimate": Topic(
            f"/{namespace}/pose_estimate",
            POSE_COV_TYPE,
            "camera-based pose estimate of base_link in map, control rate",
        ),
        "navigation": Topic(
            f"/{namespace}/navigation_status",
            NAVIGATION_STATUS_TYPE,
            "navigation state, goals reached, on change",
        ),
        "joint_states": Topic(
            f"/{namespace}/joint_states",
            JOINT_STATE_TYPE,
            "joint positions of a posed humanoid (47 joints, radians), control rate",
        ),
        "localization": Topic(
            f"/{namespace}/localization_status",
            LOCALIZATION_STATUS_TYPE,
            "observed/valid flags and age of the newest camera fix, control rate",
        ),
        "velocity_estimate": Topic(
            f"/{namespace}/velocity_estimate",
            TWIST_STAMPED_TYPE,
            "estimated forward speed and yaw rate (base_link), control rate, while the pose estimate is valid",
        ),
        "safety_state": Topic(
            f"/{namespace}/safety_state",
            SAFETY_STATE_TYPE,
            "the robot's safety tree after every tick: state, cause, TTC, zone clearance (robots with a tree)",
        ),
    }


GLOBAL_TOPICS: tuple[Topic, ...] = (
    Topic(
        CLOCK,
        CLOCK_TYPE,
        "simulated clock (bag time: recording.epoch + simulated time), at the ground-truth rate",
    ),
    Topic(TF_STATIC, TF_TYPE, "map -> camera_<id>_optical_frame for every camera, map -> <ns>/odom (once)"),
    Topic(TF, TF_TYPE, "<ns>/odom -> <ns>/base_link from the camera-based localization, control rate"),
    Topic(
        GROUND_TRUTH_POSES,
        TF_TYPE,
        "ground truth map -> ground_truth/<ns>/base_link of every agent (>= 50 Hz)",
    ),
    Topic(CONFIG, STRING_TYPE, "the resolved run config as YAML (once)"),
    Topic(RUN_INFO, RUN_INFO_TYPE, "format version, seed, package and dependency versions, renderer (once)"),
    Topic(SEMANTIC_LABELS, SEMANTIC_LABELS_TYPE, "semantic class id -> name table (once)"),
    Topic(
        RANDOMIZATION,
        STRING_TYPE,
        "what domain randomization drew (light, sun, colours, moves, distractors, paints) as JSON (once, runs with randomize on)",
    ),
    Topic(
        BIRDSEYE_IMAGE,
        COMPRESSED_IMAGE_TYPE,
        "stitched bird's-eye view, rgb8 JPEG, frame map, canvas as in the config's birdseye section (at birdseye.rate_hz, if > 0)",
    ),
    Topic(
        SAFETY_EVENTS,
        SAFETY_EVENT_TYPE,
        "safety events: robot, cause, action (stop/slow/resume), estimated pose",
    ),
    Topic(
        SAFETY_ZONES,
        MARKER_ARRAY_TYPE,
        "restricted areas as closed line strips with their names, frame map (once)",
    ),
    Topic(
        PEOPLE_DETECTIONS,
        POSE_ARRAY_TYPE,
        "people found in the cameras' segmentation images, fused, frame map, image stamp (camera rate, runs with people)",
    ),
    Topic(
        POSEMAP_SOURCE_IMAGE,
        COMPRESSED_IMAGE_TYPE,
        "the frames of a drive's image or video source (posemap.source), JPEG, at the source's rate",
    ),
    Topic(
        POSEMAP_SOURCE_LANDMARKS,
        POSE_LANDMARKS_TYPE,
        "MediaPipe Pose's landmarks of each source frame (posemap.source), what the pose mapper read",
    ),
    Topic(
        INSTANCES,
        INSTANCE_TABLE_TYPE,
        "instance id -> namespace, object name, semantic class (once, stream instance)",
    ),
    Topic(
        INSTANCE_BOXES_3D,
        INSTANCE_BOXES_3D_TYPE,
        "3D box of every instance in map: centre, size, yaw (camera rate, stream instance)",
    ),
    Topic(
        INSTANCE_BOX_MARKERS,
        MARKER_ARRAY_TYPE,
        "the 3D boxes as cubes (ns = class name, id = track id) for RViz and Foxglove (camera rate, stream instance)",
    ),
)

REQUIRED_TOPICS = (CLOCK, TF_STATIC, GROUND_TRUTH_POSES, CONFIG, RUN_INFO)

# Published once at the start and meant for every subscriber, also one that comes later: recorded
# with the QoS a ROS 2 latched publisher offers (transient local, reliable, keep last 1, as
# tf2's StaticTransformBroadcaster), so that `ros2 bag play` replays them to late subscribers too.
LATCHED_TOPICS = frozenset(
    {TF_STATIC, CONFIG, RUN_INFO, SEMANTIC_LABELS, SAFETY_ZONES, RANDOMIZATION, INSTANCES}
)
ROS_DISTRO = "jazzy"  # the message definitions the bag embeds are Jazzy's (metadata.yaml ros_distro)


def custom_msg_definitions(msg_dir: Path = MSG_DIR) -> dict[str, str]:
    """Return {msgtype: .msg text} of every custom type shipped with the package."""
    out = {}
    for path in sorted(msg_dir.glob("*/msg/*.msg")):
        out[f"{path.parent.parent.name}/msg/{path.stem}"] = path.read_text()
    return out


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    """ROS 2 (Jazzy) types plus the simlan_msgs types and the standard types rosbags lacks
    (``ros_types/``: vision_msgs)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in {**custom_msg_definitions(STANDARD_MSG_DIR), **custom_msg_definitions()}.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store
