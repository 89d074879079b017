"""Pose-mapping datasets: <landmarks per camera, joint targets> pairs as parquet (polars).

On disk (a dataset directory, written by ``python -m simlan_data.run experiment=posemap_dataset``)::

    dataset.parquet    one row per (sample, camera):
                         sample_id  u32     the sample (one body configuration)
                         camera     str     camera id ("500")
                         estimator  str     "projection" | "mediapipe"
                         detected   bool    the estimator found a person in that view
                         landmarks  f32[33, 4]  MediaPipe layout: x, y normalised, z, visibility
                         joints     f64[47] joint targets of the sample (SIMLAN's order), radians
    dataset.json       joint and landmark names, cameras (K, D, size, world_from_camera),
                       estimator, seed, samples, how it was made

A dataset's hash is the SHA-256 of its parquet bytes (generation is deterministic per seed, so
the same config gives the same hash). Splits are by sample id, never by row: the cameras of one
sample always fall in the same split.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
from numpy.typing import NDArray

from simlan_data.errors import ConfigError
from simlan_data.world.skeleton import JOINT_NAMES, LANDMARK_NAMES, NUM_JOINTS, NUM_LANDMARKS

PARQUET_NAME = "dataset.parquet"
META_NAME = "dataset.json"
FORMAT = "simlan_data.posemap.dataset/1"
SPLITS = ("train", "val", "test")


@dataclass
class PoseDataset:
    """A dataset in memory: landmarks (N, C, 33, 4), joints (N, 47), per sample and camera."""

    sample_ids: NDArray[np.int64]
    cameras: list[str]
    landmarks: NDArray[np.float32]
    joints: NDArray[np.float64]
    estimator: str
    meta: dict[str, Any] = field(default_factory=dict)
    sha256: str = ""

    def __len__(self) -> int:
        return len(self.sample_ids)

    def subset(self, mask: NDArray[np.bool_]) -> PoseDataset:
        return PoseDataset(
            self.sample_ids[mask],
            list(self.cameras),
            self.landmarks[mask],
            self.joints[mask],
            self.estimator,
            self.meta,
            self.sha256,
        )

    def select_cameras(self, cameras: list[str]) -> PoseDataset:
        missing = [c for c in cameras if c not in self.cameras]
        if missing:
            raise ConfigError(
                f"camera {missing[0]} not in the dataset",
                "posemap.cameras",
                f"the dataset has cameras {', '.join(self.cameras)}",
                "choose among them",
            )
        idx = [self.cameras.index(c) for c in cameras]
        return PoseDataset(
            self.sample_ids,
            list(cameras),
            self.landmarks[:, idx],
            self.joints,
            self.estimator,
            self.meta,
            self.sha256,
        )


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def write_dataset(directory: Path, data: PoseDataset) -> str:
    """Write ``dataset.parquet`` and ``dataset.json`` into ``directory``; returns the parquet's SHA-256."""
    n, c = data.landmarks.shape[:2]
    directory.mkdir(parents=True, exist_ok=True)
    lm = data.landmarks.reshape(n * c, NUM_LANDMARKS, 4).astype(np.float32)
    df = pl.DataFrame(
        {
            "sample_id": np.repeat(data.sample_ids, c).astype(np.uint32),
            "camera": np.tile(np.array(data.cameras, dtype=object), n).tolist(),
            "estimator": [data.estimator] * (n * c),
            "detected": (lm[:, :, 3] > 0).any(axis=1),
            "landmarks": lm,
            "joints": np.repeat(data.joints, c, axis=0).astype(np.float64),
        }
    )
    path = directory / PARQUET_NAME
    df.write_parquet(path, compression="zstd", statistics=False)
    digest = sha256_file(path)
    meta = {
        "format": FORMAT,
        "joint_names": list(JOINT_NAMES),
        "landmark_names": list(LANDMARK_NAMES),
        "cameras": list(data.cameras),
        "estimator": data.estimator,
        "samples": int(n),
        "sha256": digest,
        **data.meta,
    }
    (directory / META_NAME).write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return digest


def resolve_dataset(path: str) -> Path:
    """The parquet file of a dataset given as a file or a (run) directory."""
    p = Path(path)
    if p.is_dir():
        p = p / PARQUET_NAME
    if not p.is_file():
        raise ConfigError(
            "dataset not found",
            f"posemap.dataset={path}",
            f"no {PARQUET_NAME} there",
            "give a dataset run directory or its dataset.parquet (python -m simlan_data.run experiment=posemap_dataset)",
        )
    return p


def read_dataset(path: str) -> PoseDataset:
    """Read a dataset (file or directory); an empty or malformed one is a ConfigError."""
    p = resolve_dataset(path)
    try:
        df = pl.read_parquet(p)
    except Exception as err:
        raise ConfigError(
            "cannot read dataset", str(p), f"{type(err).__name__}: {err}", "regenerate it"
        ) from err
    need = {"sample_id", "camera", "estimator", "landmarks", "joints"}
    if not need <= set(df.columns):
        raise ConfigError(
            "not a pose-mapping dataset",
            str(p),
            f"missing columns {sorted(need - set(df.columns))}",
            "regenerate it",
        )
    if df.height == 0:
        raise ConfigError(
            "empty dataset", str(p), "it has no samples", "generate one with posemap.samples > 0"
        )
    df = df.sort(["sample_id", "camera"])
    cameras = sorted(df["camera"].unique().to_list())
    ids = df["sample_id"].unique().sort().to_numpy().astype(np.int64)
    if df.height != len(ids) * len(cameras):
        raise ConfigError(
            "incomplete dataset", str(p), "not every sample has a row for every camera", "regenerate it"
        )
    lm = df["landmarks"].to_numpy().astype(np.float32).reshape(len(ids), len(cameras), NUM_LANDMARKS, 4)
    joints = df["joints"].to_numpy().reshape(len(ids), len(cameras), -1)[:, 0]
    if joints.shape[1] != NUM_JOINTS:
        raise ConfigError(
            "dataset has the wrong number of joints",
            str(p),
            f"{joints.shape[1]} instead of {NUM_JOINTS}",
            "regenerate it",
        )
    estimators = df["estimator"].unique().to_list()
    meta_path = p.with_name(META_NAME)
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    return PoseDataset(
        ids, cameras, lm, joints.astype(np.float64), ",".join(sorted(estimators)), meta, sha256_file(p)
    )


def split_of(sample_ids: NDArray[np.int64], *, val_fraction: float, test_fraction: float) -> NDArray[np.str_]:
    """Split name per sample from a hash of its id (stable when a dataset grows or shrinks)."""
    x = sample_ids.astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
    with np.errstate(over="ignore"):  # splitmix64
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        x = x ^ (x >> np.uint64(31))
    u = (x >> np.uint64(11)).astype(np.float64) / float(1 << 53)
    return np.where(u < test_fraction, "test", np.where(u < test_fraction + val_fraction, "val", "train"))
