"""Pose mappers: feature vectors -> the 47 joint targets (radians).

- :class:`MLPMapper` (torch): fully connected ReLU layers with dropout, Adam(W), MSE (or L1:
  the conditional median, which is what the MAE rewards where the landmarks cannot tell joints
  apart) on standardised targets; keeps the epoch with the best validation MAE. With SIMLAN's hidden sizes
  [504, 476, 479] on one camera's x, y, z it is SIMLAN's baseline (``model=mlp``); on the rig
  features of all cameras it is the multi-view fusion model (``model=fusion``).
- :class:`GBMMapper` (scikit-learn): one HistGradientBoostingRegressor per joint, in place of
  SIMLAN's AutoGluon ensemble (``model=gbm``).

Both standardise inputs and targets with the training split's mean and deviation, clip their
predictions to the joint limits and save to / load from a directory (``model.json`` + weights).
"""

from __future__ import annotations

import json
import logging
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simlan_data.errors import ConfigError
from simlan_data.world.skeleton import LOWER, UPPER

log = logging.getLogger(__name__)

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


@dataclass
class Standardizer:
    mean: F64
    std: F64

    @staticmethod
    def fit(x: NDArray[Any]) -> Standardizer:
        std = x.std(axis=0)
        return Standardizer(
            x.mean(axis=0).astype(np.float64), np.where(std > 1e-8, std, 1.0).astype(np.float64)
        )

    def apply(self, x: NDArray[Any]) -> F32:
        return ((x - self.mean) / self.std).astype(np.float32)

    def invert(self, y: NDArray[Any]) -> F64:
        return np.asarray(y, dtype=np.float64) * self.std + self.mean

    def to_dict(self) -> dict:
        return {"mean": self.mean.tolist(), "std": self.std.tolist()}

    @staticmethod
    def from_dict(d: dict) -> Standardizer:
        return Standardizer(np.asarray(d["mean"], dtype=np.float64), np.asarray(d["std"], dtype=np.float64))


@dataclass
class TrainParams:
    hidden: list[int] = field(default_factory=lambda: [504, 476, 479])
    dropout: float = 0.1
    loss: str = "mse"  # mse | l1
    lr: float = 1e-3
    weight_decay: float = 0.0
    epochs: int = 200
    batch_size: int = 256
    gbm_iterations: int = 300
    threads: int = 2
    seed: int = 0


class PoseMapper:
    """Interface of every model: fit on (features, joints), predict joints, save and load."""

    kind = ""

    def __init__(self, params: TrainParams) -> None:
        self.params = params
        self.x_norm: Standardizer | None = None
        self.y_norm: Standardizer | None = None
        self.history: list[dict[str, float]] = []

    def fit(self, x: F32, y: F64, x_val: F32, y_val: F64, *, progress: bool = False) -> None:
        raise NotImplementedError

    def _predict_normalised(self, x: F32) -> NDArray[Any]:
        raise NotImplementedError

    def predict(self, x: F32) -> F64:
        assert self.x_norm is not None and self.y_norm is not None, "fit or load the model first"
        y = self.y_norm.invert(self._predict_normalised(self.x_norm.apply(np.atleast_2d(x))))
        return np.clip(y, LOWER, UPPER)

    def _save_weights(self, directory: Path) -> None:
        raise NotImplementedError

    def _load_weights(self, directory: Path, info: dict) -> None:
        raise NotImplementedError

    def save(self, directory: Path, info: dict) -> None:
        assert self.x_norm is not None and self.y_norm is not None
        directory.mkdir(parents=True, exist_ok=True)
        self._save_weights(directory)
        doc = {
            **info,
            "kind": self.kind,
            "params": self.params.__dict__,
            "x_norm": self.x_norm.to_dict(),
            "y_norm": self.y_norm.to_dict(),
            "history": self.history,
        }
        (directory / "model.json").write_text(json.dumps(doc, indent=1) + "\n")


def _torch() -> Any:
    """torch, which only the MLP pose mapper needs: an optional install (``pip install -e
    ".[posemap]"``), so the base install has no torch; without it one line says so."""
    try:
        import torch
    except ImportError as err:
        raise ConfigError(
            "the pose-mapping models mlp and fusion need torch",
            "this installation",
            f"torch is not installed ({err})",
            'install the pose-mapping extra: pip install -e ".[posemap]" (or train posemap.model=gbm)',
        ) from None
    return torch


def _mae_rad(y_pred: F64, y: F64) -> float:
    return float(np.abs(y_pred - y).mean())


class MLPMapper(PoseMapper):
    kind = "mlp"

    def _net(self, n_in: int, n_out: int) -> Any:
        torch = _torch()

        layers: list[Any] = []  # torch.nn modules (torch is an optional install)
        width = n_in
        for h in self.params.hidden:
            layers += [torch.nn.Linear(width, h), torch.nn.ReLU(), torch.nn.Dropout(self.params.dropout)]
            width = h
        layers.append(torch.nn.Linear(width, n_out))
        return torch.nn.Sequential(*layers)

    def fit(self, x: F32, y: F64, x_val: F32, y_val: F64, *, progress: bool = False) -> None:
        torch = _torch()

        p = self.params
        torch.manual_seed(p.seed)
        torch.set_num_threads(p.threads)
        self.x_norm, self.y_norm = Standardizer.fit(x), Standardizer.fit(y)
        xt = torch.from_numpy(self.x_norm.apply(x))
        yt = torch.from_numpy(self.y_norm.apply(y))
        xv = torch.from_numpy(self.x_norm.apply(x_val))
        self.net = self._net(x.shape[1], y.shape[1])
        opt = torch.optim.AdamW(self.net.parameters(), lr=p.lr, weight_decay=p.weight_decay)
        sched = torch.optim.lr_scheduler.OneCycleLR(
            opt, max_lr=p.lr, total_steps=p.epochs * max(1, -(-len(xt) // p.batch_size)), pct_start=0.1
        )
        loss_fn = torch.nn.L1Loss() if p.loss == "l1" else torch.nn.MSELoss()
        gen = torch.Generator().manual_seed(p.seed)
        best, best_state = np.inf, None
        for epoch in range(p.epochs):
            t0 = time.perf_counter()
            self.net.train()
            order = torch.randperm(len(xt), generator=gen)
            total = 0.0
            for i in range(0, len(xt), p.batch_size):
                idx = order[i : i + p.batch_size]
                opt.zero_grad()
                loss = loss_fn(self.net(xt[idx]), yt[idx])
                loss.backward()
                opt.step()
                sched.step()
                total += float(loss.detach()) * len(idx)
            val_mae = _mae_rad(self.predict_from_tensor(xv), y_val) if len(x_val) else np.nan
            self.history.append(
                {
                    "epoch": epoch,
                    "train_mse": total / len(xt),
                    "val_mae_rad": val_mae,
                    "s": time.perf_counter() - t0,
                }
            )
            if progress and (epoch % 10 == 0 or epoch == p.epochs - 1):
                log.info("  epoch %4d  train mse %.4f  val MAE %.4f rad", epoch, total / len(xt), val_mae)
            if not len(x_val) or val_mae < best:
                best = val_mae
                best_state = {k: v.detach().clone() for k, v in self.net.state_dict().items()}
        if best_state is not None:
            self.net.load_state_dict(best_state)
        self.net.eval()

    def predict_from_tensor(self, xv: Any) -> F64:
        torch = _torch()

        assert self.y_norm is not None
        self.net.eval()
        with torch.no_grad():
            y = self.net(xv).numpy()
        return np.clip(self.y_norm.invert(y), LOWER, UPPER)

    def _predict_normalised(self, x: F32) -> NDArray[Any]:
        torch = _torch()

        self.net.eval()
        with torch.no_grad():
            return self.net(torch.from_numpy(x)).numpy()

    def _save_weights(self, directory: Path) -> None:
        torch = _torch()

        torch.save(self.net.state_dict(), directory / "model.pt")

    def _load_weights(self, directory: Path, info: dict) -> None:
        torch = _torch()

        n_in = len(info["x_norm"]["mean"])
        n_out = len(info["y_norm"]["mean"])
        self.net = self._net(n_in, n_out)
        self.net.load_state_dict(torch.load(directory / "model.pt", weights_only=True))
        self.net.eval()


class GBMMapper(PoseMapper):
    kind = "gbm"

    def fit(self, x: F32, y: F64, x_val: F32, y_val: F64, *, progress: bool = False) -> None:
        from sklearn.ensemble import HistGradientBoostingRegressor
        from threadpoolctl import threadpool_limits

        p = self.params
        self.x_norm, self.y_norm = Standardizer.fit(x), Standardizer.fit(y)
        xs, ys = self.x_norm.apply(x), self.y_norm.apply(y)
        self.models = []
        limit = threadpool_limits(limits=p.threads)  # OpenMP spin-waits badly on oversubscribed cores
        for j in range(y.shape[1]):
            m = HistGradientBoostingRegressor(
                loss="absolute_error" if p.loss == "l1" else "squared_error",
                max_iter=p.gbm_iterations,
                learning_rate=0.1,
                max_leaf_nodes=31,
                early_stopping=True,
                validation_fraction=0.1,
                n_iter_no_change=20,
                random_state=p.seed + j,
            )
            m.fit(xs, ys[:, j])
            self.models.append(m)
            if progress:
                log.info("  joint %d/%d: %d trees", j + 1, y.shape[1], m.n_iter_)
        limit.restore_original_limits()
        val_mae = _mae_rad(self.predict(x_val), y_val) if len(x_val) else np.nan
        self.history.append({"val_mae_rad": val_mae})

    def _predict_normalised(self, x: F32) -> NDArray[Any]:
        return np.stack([m.predict(x) for m in self.models], axis=1)

    def _save_weights(self, directory: Path) -> None:
        with open(directory / "model.pkl", "wb") as f:
            pickle.dump(self.models, f)

    def _load_weights(self, directory: Path, info: dict) -> None:  # noqa: ARG002 - same interface
        with open(directory / "model.pkl", "rb") as f:
            self.models = pickle.load(f)


MAPPERS: dict[str, type[PoseMapper]] = {"mlp": MLPMapper, "fusion": MLPMapper, "gbm": GBMMapper}


def load_mapper(directory: Path) -> tuple[PoseMapper, dict]:
    """A saved model and its ``model.json`` (config, dataset hash, features, metrics)."""
    info = json.loads((directory / "model.json").read_text())
    params = TrainParams(**info["params"])
    mapper = MAPPERS[info["kind"]](params)
    mapper.x_norm = Standardizer.from_dict(info["x_norm"])
    mapper.y_norm = Standardizer.from_dict(info["y_norm"])
    mapper.history = info.get("history", [])
    mapper._load_weights(directory, info)
    return mapper, info
