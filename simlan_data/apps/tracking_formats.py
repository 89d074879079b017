"""Tracking dataset writers for ``python -m simlan_data.export``: MOTChallenge per camera and the
AI City Challenge multi-camera tracking text (issue 25).

Like the detection writers (:mod:`simlan_data.apps.dataset_formats`) they take one annotated frame
at a time and write the index files at the end, so an export holds one frame in memory; rows are
written in the bag's time order, so the same recording gives the same bytes.

Track ids are the recording's instance ids: one object has one id in every camera and at every
time, which is what both formats ask of their ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.apps.dataset_formats import AnnotatedFrame, InstanceInfo

MOT_BENCHMARK = "SIMLAN"  # the BENCHMARK of TrackEval's MotChallenge2DBox config
MOT_SPLIT = "train"  # its SPLIT_TO_EVAL
MOT_CLASS = 1  # MOTChallenge's class column: 1 ("pedestrian"), the class TrackEval evaluates
AICITY_TXT = "ground_truth.txt"  # the AI City Challenge 2024 track 1 scene file's name
INSTANCES_CSV = "instances.csv"  # track id -> namespace, name, class (both formats)
BOXES = ("visible", "amodal")


def mot_sequence(camera_id: str) -> str:
    """The MOTChallenge sequence name of a camera."""
    return f"camera_{camera_id}"


def _box(frame: AnnotatedFrame, k: int, box: str) -> tuple[float, float, float, float]:
    """Box ``k`` of a frame as x y w h: the visible box (integers) or the amodal box (clipped)."""
    if box == "visible":
        u0, v0, u1, v1 = (int(x) for x in frame.visible[k])
        return u0, v0, u1 - u0, v1 - v0
    a0, b0, a1, b1 = (round(float(x), 2) for x in frame.amodal[k])
    return a0, b0, round(a1 - a0, 2), round(b1 - b0, 2)


def _fmt(value: float) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def _write_instances(path: Path, objects: dict[int, InstanceInfo], class_names: dict[int, str]) -> None:
    rows = [
        f"{o.id},{o.namespace},{o.name},{o.class_id},{class_names.get(o.class_id, str(o.class_id))}\n"
        for o in sorted(objects.values(), key=lambda o: o.id)
    ]
    path.write_text("id,namespace,name,class_id,class_name\n" + "".join(rows))


@dataclass
class _Sequence:
    """One camera's MOTChallenge sequence while it is written."""

    root: Path
    gt: IO[str]
    width: int
    height: int
    first_ns: int
    last_ns: int = 0
    length: int = 0
    rows: int = 0
    images: list[Path] = field(default_factory=list)


class _TrackingWriter:
    """What both tracking formats are made of: the output folder, the instance table, the class
    names and which 2D box they write (``visible`` or ``amodal``)."""

    def __init__(
        self,
        out: Path,
        objects: dict[int, InstanceInfo],
        class_names: dict[int, str],
        *,
        box: str = "visible",
    ) -> None:
        self.out, self.objects, self.class_names, self.box = out, objects, class_names, box
        self._open()

    def _open(self) -> None:
        """Create what the format writes into (its folders, its files)."""
        raise NotImplementedError


class MotWriter(_TrackingWriter):
    """MOTChallenge ground truth, one sequence per camera, in the layout TrackEval's
    ``MotChallenge2DBox`` reads with ``GT_FOLDER=<out>``, ``BENCHMARK=SIMLAN``, ``SPLIT_TO_EVAL=train``::

        <out>/SIMLAN-train/camera_<id>/img1/000001.jpg ...   frames, 1-based
        <out>/SIMLAN-train/camera_<id>/gt/gt.txt              frame,id,left,top,width,height,conf,class,visibility
        <out>/SIMLAN-train/camera_<id>/seqinfo.ini
        <out>/seqmaps/SIMLAN-train.txt                        name, then one sequence a line
        <out>/instances.csv                                   track id -> namespace, name, class
    """

    def _open(self) -> None:
        out = self.out
        self.split = out / f"{MOT_BENCHMARK}-{MOT_SPLIT}"
        self.split.mkdir(parents=True)
        (out / "seqmaps").mkdir()
        self.sequences: dict[str, _Sequence] = {}
        self.image_count = self.annotation_count = 0

    def _sequence(self, frame: AnnotatedFrame) -> _Sequence:
        seq = self.sequences.get(frame.camera_id)
        if seq is None:
            root = self.split / mot_sequence(frame.camera_id)
            (root / "img1").mkdir(parents=True)
            (root / "gt").mkdir()
            gt = (root / "gt" / "gt.txt").open("w")
            seq = _Sequence(root, gt, frame.width, frame.height, frame.stamp_ns)
            self.sequences[frame.camera_id] = seq
        return seq

    def add(self, frame: AnnotatedFrame) -> None:
        seq = self._sequence(frame)
        number = frame.index + 1  # MOTChallenge frames count from 1
        image = seq.root / "img1" / f"{number:06d}.jpg"
        image.write_bytes(frame.jpeg)
        seq.images.append(image)
        seq.length, seq.last_ns = number, frame.stamp_ns
        for k, iid in enumerate(frame.ids.tolist()):
            if iid not in self.objects:
                continue
            x, y, w, h = (_fmt(v) for v in _box(frame, k, self.box))
            visibility = round(float(frame.visible_fraction[k]), 6)
            seq.gt.write(f"{number},{iid},{x},{y},{w},{h},1,{MOT_CLASS},{visibility:g}\n")
            seq.rows += 1
            self.annotation_count += 1
        self.image_count += 1

    def finish(self, info: dict[str, Any]) -> None:
        del info
        for seq in self.sequences.values():
            seq.gt.close()
            (seq.root / "seqinfo.ini").write_text(
                "[Sequence]\n"
                f"name={seq.root.name}\nimDir=img1\nframeRate={_frame_rate(seq)}\n"
                f"seqLength={seq.length}\nimWidth={seq.width}\nimHeight={seq.height}\nimExt=.jpg\n"
            )
        names = sorted(s.root.name for s in self.sequences.values())
        (self.out / "seqmaps" / f"{MOT_BENCHMARK}-{MOT_SPLIT}.txt").write_text(
            "name\n" + "".join(f"{n}\n" for n in names)
        )
        _write_instances(self.out / INSTANCES_CSV, self.objects, self.class_names)

    @property
    def files(self) -> list[Path]:
        out = [self.out / INSTANCES_CSV, self.out / "seqmaps" / f"{MOT_BENCHMARK}-{MOT_SPLIT}.txt"]
        for seq in self.sequences.values():
            out += [seq.root / "seqinfo.ini", seq.root / "gt" / "gt.txt", *seq.images]
        return out


def _frame_rate(seq: _Sequence) -> int:
    """Frames per second of a sequence from its first and last stamps (seqinfo.ini holds an integer)."""
    if seq.length < 2 or seq.last_ns <= seq.first_ns:
        return 1
    return max(1, round((seq.length - 1) * 1e9 / (seq.last_ns - seq.first_ns)))


class AiCityWriter(_TrackingWriter):
    """The AI City Challenge 2024 track 1 (multi-camera people tracking) ground-truth text: one
    file for all cameras, one space-separated line per object seen in a camera frame::

        camera_id obj_id frame_id xmin ymin width height xworld yworld

    ``frame_id`` counts each camera's frames from 0; the box is the 2D box (``--box``) in pixels;
    ``xworld yworld`` is the object's 3D box centre in ``map`` (metres) at the frame's camera tick,
    which for a yaw-aligned box is its bottom centre's ground point, what AI City asks for. Beside
    it ``instances.csv`` names each track's class (AI City's scenes track people only; ours also
    robots, pallet trucks, pallets and boxes).
    """

    def _open(self) -> None:
        out = self.out
        self._txt: IO[str] = (out / AICITY_TXT).open("w")
        self.files: list[Path] = [out / AICITY_TXT, out / INSTANCES_CSV]
        self.image_count = self.annotation_count = 0

    def add(self, frame: AnnotatedFrame) -> None:
        world = _world_of(frame)
        for k, iid in enumerate(frame.ids.tolist()):
            if iid not in self.objects or iid not in world:
                continue
            x, y, w, h = (_fmt(v) for v in _box(frame, k, self.box))
            xw, yw = world[iid]
            self._txt.write(f"{frame.camera_id} {iid} {frame.index} {x} {y} {w} {h} {xw:.6f} {yw:.6f}\n")
            self.annotation_count += 1
        self.image_count += 1

    def finish(self, info: dict[str, Any]) -> None:
        del info
        self._txt.close()
        _write_instances(self.out / INSTANCES_CSV, self.objects, self.class_names)


def _world_of(frame: AnnotatedFrame) -> dict[int, tuple[float, float]]:
    centers: NDArray[np.float64] = frame.world_centers
    return {
        int(i): (float(c[0]), float(c[1])) for i, c in zip(frame.world_ids.tolist(), centers, strict=True)
    }
