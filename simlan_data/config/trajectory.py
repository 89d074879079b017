"""Real tracker trajectories drive agents (``experiment=trajectory``, issue 25 item 6).

The ``trajectory`` section names a tracker file in SIMLAN's replay format, a JSON list of
``{"time_stamp": <ms>, "object_list": [[id, x, y, z, yaw], ...]}``, and which agent type each
tracker id becomes. The resolvers ``${trajectory:agents}`` and ``${trajectory:duration_s}`` turn it
into the run's ``agents`` (``robot_agent_<id>``, marker id = tracker id, spawned where the object
is first seen) and its duration (the file's span), so the recorded config holds both. The motion
itself (interpolation, yaw from motion, hiding absent objects) is ``simlan_data.sim.trajectory_drive``
over :class:`simlan_data.algorithms.trajectory.Tracks`.

Every check fails as one line naming the field, the value and the fix (exit 2).
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from simlan_data.algorithms.trajectory import Tracks
from simlan_data.constants import ASSETS_DIR
from simlan_data.errors import ConfigError
from simlan_data.world.agent_types import AGENT_TYPES

__all__ = ["TrajectoryConfig", "load_tracks", "resolve"]

KINEMATIC = ("diff", "walker", "static")  # types a trajectory can move (not the posed humanoid)
_bad = ConfigError.invalid
_FIELD = "trajectory.file"
TRAJECTORIES_DIR = ASSETS_DIR / "trajectories"


@dataclass
class TrajectoryConfig:
    """The ``trajectory`` section: a tracker file and the agent type of each tracker id."""

    file: str = ""  # SIMLAN replay JSON; empty: no trajectory (experiment=trajectory needs one)
    default_type: str = "pallet_truck"  # the agent type of every tracker id not in ``types``
    types: dict[str, str] = field(default_factory=dict)  # per tracker id (+trajectory.types.41=humanoid)
    yaw: str = "auto"  # auto (the file's where it varies, else from motion) | file | motion
    min_move_m: float = 0.02  # yaw from motion: heading to the next position at least this far
    yaw_smoothing: float = 0.3  # low-pass factor per stamp (SIMLAN's angular_smoothing_factor)
    max_yaw_step_rad: float = 0.5  # at most this much turn per stamp (SIMLAN's max_angular_change)

    def check(self) -> None:
        for key, name in [
            ("default_type", self.default_type),
            *((f"types.{k}", v) for k, v in self.types.items()),
        ]:
            kind = AGENT_TYPES.get(name)
            if kind is None or kind.drive not in KINEMATIC:
                ok = ", ".join(n for n, t in AGENT_TYPES.items() if t.drive in KINEMATIC)
                raise _bad(
                    f"trajectory.{key}", name, "not an agent type a trajectory can move", f"use one of {ok}"
                )
        for k in self.types:
            if not k.isdigit():
                raise _bad(
                    f"trajectory.types.{k}",
                    self.types[k],
                    "keys are tracker ids",
                    "use e.g. +trajectory.types.41=humanoid",
                )
        if self.yaw not in ("auto", "file", "motion"):
            raise _bad("trajectory.yaw", self.yaw, "known: auto, file, motion", "use trajectory.yaw=auto")
        if not 0 < self.yaw_smoothing <= 1:
            raise _bad("trajectory.yaw_smoothing", self.yaw_smoothing, "must be within (0, 1]", "use 0.3")
        if self.max_yaw_step_rad <= 0 or self.min_move_m < 0:
            raise _bad("trajectory.max_yaw_step_rad", self.max_yaw_step_rad, "must be > 0", "use 0.5")

    def check_agents(self, namespaces: list[str]) -> None:
        """With a file, the run's agents must be the file's (``agents: ${trajectory:agents}``)."""
        if not self.file:
            return
        want = sorted(f"robot_agent_{oid}" for oid in load_tracks(self).ids)
        if sorted(namespaces) != want:
            raise _bad(
                _FIELD,
                self.file,
                f"the run's agents {sorted(namespaces)} are not the file's {want}",
                "run it with experiment=trajectory (its agents come from the file)",
            )

    def type_of(self, oid: int) -> str:
        return self.types.get(str(oid), self.default_type)


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _row(row: Any, where: str) -> tuple[int, float, float, float, float]:
    """One ``[id, x, y, z, yaw]`` (yaw may be null: estimated from motion)."""
    ok = isinstance(row, list) and len(row) == 5 and isinstance(row[0], int) and not isinstance(row[0], bool)
    ok = ok and all(_number(v) for v in row[1:4]) and (row[4] is None or _number(row[4]))
    if not ok:
        raise _bad(
            where,
            row,
            "expected [id, x_m, y_m, z_m, yaw_rad] (integer id, numbers; yaw may be null)",
            "fix the tracker file",
        )
    if not 0 <= row[0] < 1000:
        raise _bad(where, row, "tracker ids become marker ids: 0..999", "renumber the tracker's ids")
    return (
        int(row[0]),
        float(row[1]),
        float(row[2]),
        float(row[3]),
        math.nan if row[4] is None else float(row[4]),
    )


@functools.lru_cache(maxsize=4)
def _parse(path: str, mtime_ns: int) -> Tracks:  # noqa: ARG001 - part of the cache key
    try:
        data = json.loads(Path(path).read_text())
    except OSError as err:
        raise _bad(
            _FIELD, path, f"cannot read it ({err.strerror})", "give an existing tracker JSON file"
        ) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise _bad(
            _FIELD, path, f"not JSON ({err})", "give a tracker JSON file (a list of time_stamp/object_list)"
        ) from None
    if not isinstance(data, list) or not data:
        raise _bad(_FIELD, path, "expected a non-empty JSON list of stamps", "give a tracker JSON file")
    stamps: list[int] = []
    rows: list[list[tuple[int, float, float, float, float]]] = []
    for i, entry in enumerate(data):
        where = f"{_FIELD}[{i}]"
        if (
            not isinstance(entry, dict)
            or not isinstance(entry.get("time_stamp"), int)
            or not isinstance(entry.get("object_list"), list)
        ):
            raise _bad(
                where,
                str(entry)[:80],
                "expected {time_stamp: <ms, integer>, object_list: [...]}",
                "fix the tracker file",
            )
        if stamps and entry["time_stamp"] <= stamps[-1]:
            raise _bad(
                f"{where}.time_stamp",
                entry["time_stamp"],
                f"stamps must increase (previous {stamps[-1]})",
                "sort the file by time_stamp and drop repeats",
            )
        stamp_rows = [_row(r, f"{where}.object_list[{j}]") for j, r in enumerate(entry["object_list"])]
        if len({r[0] for r in stamp_rows}) != len(stamp_rows):
            raise _bad(
                f"{where}.object_list",
                [r[0] for r in stamp_rows],
                "an id appears twice at one stamp",
                "fix the tracker file",
            )
        stamps.append(int(entry["time_stamp"]))
        rows.append(stamp_rows)
    if len(stamps) < 2:
        raise _bad(
            _FIELD,
            path,
            "needs at least two stamps (the run lasts the file's span)",
            "give a longer trajectory",
        )
    tracks = Tracks.from_rows(stamps, rows)
    if not tracks.ids:
        raise _bad(_FIELD, path, "no object in any stamp", "give a trajectory with objects")
    return tracks


def load_tracks(cfg: TrajectoryConfig) -> Tracks:
    """The file's tracks, yaw as ``cfg.yaw`` says (the file's or from motion)."""
    if not cfg.file:
        raise _bad(_FIELD, "", "experiment=trajectory needs a tracker file", "add trajectory.file=PATH")
    path = Path(cfg.file).expanduser()
    if not path.exists() and (TRAJECTORIES_DIR / cfg.file).is_file():  # a packaged trajectory by name
        path = TRAJECTORIES_DIR / cfg.file
    mtime = path.stat().st_mtime_ns if path.is_file() else 0
    tracks = _parse(str(path), mtime)
    if cfg.yaw == "file":
        return tracks
    faker = {
        "min_move_m": cfg.min_move_m,
        "smoothing": cfg.yaw_smoothing,
        "max_step_rad": cfg.max_yaw_step_rad,
    }
    if cfg.yaw == "motion":
        tracks = Tracks(tracks.ids, tracks.stamps_ns, tracks.xyz, tracks.yaw * math.nan, t0_ms=tracks.t0_ms)
    return tracks.with_yaw_from_motion(**faker)


def resolve(key: str, section: Mapping[Any, Any]) -> Any:
    """Value of ``${trajectory:KEY}`` (``agents``, ``duration_s``) for the ``trajectory`` section."""
    cfg = TrajectoryConfig(**dict(section))
    cfg.check()
    tracks = load_tracks(cfg)
    if key == "duration_s":
        return tracks.duration_s
    if key == "epoch":  # the bag's time = the file's: exported stamps equal the file's
        start = datetime.fromtimestamp(tracks.t0_ms / 1000, tz=timezone.utc)
        return start.isoformat(timespec="milliseconds")
    if key == "agents":
        agents = {}
        for oid in tracks.ids:
            x, y, yaw = tracks.first_pose(oid)
            agents[f"robot_agent_{oid}"] = {
                "type": cfg.type_of(oid),
                "pose": [x, y, float(math.remainder(yaw, 2 * math.pi))],
            }
        return agents
    raise KeyError(f"unknown trajectory key {key!r}; known: agents, duration_s, epoch")
