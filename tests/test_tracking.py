"""Tracking metrics in the V&V layer (issue 25, item 4): replay algorithm ``tracking`` scores a
tracker's MOTChallenge folder or AI City file, or the recording's localizer, with TrackEval's HOTA,
CLEAR and Identity, per camera and in world coordinates. Real recording (tests/test_export.py's
2 s run with stream instance, made once per session), real exports, real TrackEval."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from test_export import _trackeval, made  # the same run and TrackEval's own MOT scoring

from conftest import run_cli
from simlan_data.apps.replay import main as replay_main
from simlan_data.errors import ConfigError
from simlan_data.evaluation.tracking_metrics import Timestep, distance_similarity, evaluate

__all__ = ["made"]  # (a fixture: pytest finds it here through the import)

CAMERAS = ("160", "161", "162")


def _replay(run: Path, out: Path, *options: str) -> dict[str, float]:
    """``python -m simlan_data.replay RUN --out OUT --algorithms tracking --set ...`` in process."""
    args = [str(run), "--out", str(out), "--algorithms", "tracking"]
    for option in options:
        args += ["--set", option]
    with pytest.raises(SystemExit) as done:
        raise SystemExit(replay_main(args))
    assert done.value.code == 0
    return json.loads((out / "metrics.json").read_text())


def _mot_rows(made: Path) -> dict[str, list[list[str]]]:
    return {
        cid: [
            line.split(",")
            for line in (made / "mot" / "SIMLAN-train" / f"camera_{cid}" / "gt" / "gt.txt")
            .read_text()
            .splitlines()
        ]
        for cid in CAMERAS
    }


def _tracker(root: Path, name: str, rows: dict[str, list[list[str]]]) -> Path:
    """A MOTChallenge tracker folder, in the layout TrackEval reads (``<root>/SIMLAN-train/<name>/data``)."""
    data = root / "SIMLAN-train" / name / "data"
    data.mkdir(parents=True)
    for cid, lines in rows.items():
        (data / f"camera_{cid}.txt").write_text("".join(",".join(r) + "\n" for r in lines))
    return data


def test_ground_truth_as_tracker_scores_one(made: Path, tmp_path: Path) -> None:
    tracks = _tracker(tmp_path / "trackers", "self", _mot_rows(made))
    proc = run_cli(
        str(made / "run"), "--out", str(tmp_path / "mot"), "--algorithms", "tracking",
        "--set", f"tracks={tracks}", module="simlan_data.replay",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    m = json.loads((tmp_path / "mot" / "metrics.json").read_text())
    assert (m["tracking.camera.hota"], m["tracking.camera.mota"], m["tracking.camera.idf1"]) == (
        1.0,
        1.0,
        1.0,
    )
    assert m["tracking.camera.gt_dets"] == m["tracking.camera.tracker_dets"] >= 10
    assert "tracking.hota" not in m  # a MOTChallenge folder has no world positions
    csv = (tmp_path / "mot" / "tracking.csv").read_text().splitlines()
    assert csv[0] == "sequence,metric,value" and "camera_160,hota,1" in csv
    # the AI City file: per camera and in world coordinates
    m = _replay(made / "run", tmp_path / "aicity", f"tracks={made / 'aicity' / 'ground_truth.txt'}")
    for prefix in ("tracking", "tracking.camera"):
        assert (m[f"{prefix}.hota"], m[f"{prefix}.mota"], m[f"{prefix}.idf1"]) == (1.0, 1.0, 1.0), prefix
    assert m["tracking.gt_dets"] >= 10


def test_camera_scores_are_trackevals_own(made: Path, tmp_path: Path) -> None:
    """A swapped id lowers IDF1, dropped frames lower MOTA; each camera's numbers equal TrackEval's
    MotChallenge2DBox on the MOT export (its dataset code, not ours, reading the same files)."""
    rows = _mot_rows(made)
    busiest = max(CAMERAS, key=lambda c: len(rows[c]))
    swapped = {c: [list(r) for r in rs] for c, rs in rows.items()}
    mine = [r for r in swapped[busiest] if r[1] == swapped[busiest][0][1]]
    for r in mine[len(mine) // 2 :]:
        r[1] = "999"
    dropped = {c: [r for r in rs if int(r[0]) % 3 != 0] for c, rs in rows.items()}  # every 3rd frame
    root = tmp_path / "trackers"
    for name, tracks in (("swapped", swapped), ("dropped", dropped)):
        _tracker(root, name, tracks)
    reference = _trackeval(made / "mot", root)
    for name in ("swapped", "dropped"):
        m = _replay(made / "run", tmp_path / name, f"tracks={root / 'SIMLAN-train' / name}")
        got = {k: m[f"tracking.camera.{k.lower()}"] for k in ("HOTA", "MOTA", "IDF1", "IDSW")}
        assert got == pytest.approx(reference[name], abs=1e-9), name
    assert reference["swapped"]["IDF1"] < 0.9 and reference["swapped"]["MOTA"] < 1.0
    assert reference["dropped"]["MOTA"] < 0.8 and reference["dropped"]["IDF1"] < 1.0


def test_localizer_scores_high_in_world_coordinates(made: Path, tmp_path: Path) -> None:
    """The marker localizer's estimates of the robot, at its estimated 3D box centre.

    Measured on this run (seed 5, 2 s, 11 camera ticks): world HOTA 1.0 (every distance under
    0.1 m), LocA 0.9991 (a mean distance of 1.7 mm), MOTA = IDF1 = 1; its projected boxes against
    the amodal boxes: HOTA 1.0, LocA (mean IoU) 0.990. Bounds leave room for the renderer and the localizer's numerics, not for a lost
    or swapped track (MOTA and IDF1 must stay 1)."""
    m = _replay(made / "run", tmp_path / "loc")
    assert m["tracking.gt_dets"] >= 5
    assert m["tracking.mota"] == 1.0 and m["tracking.idf1"] == 1.0 and m["tracking.idsw"] == 0
    assert m["tracking.hota"] >= 0.98 and m["tracking.loca"] >= 0.99
    assert m["tracking.camera.mota"] >= 0.9 and m["tracking.camera.hota"] >= 0.9


def test_world_similarity_threshold_is_one_metre() -> None:
    """At the default 2 m zero distance, TrackEval's 0.5 similarity threshold is 1 m: 0.9 m off
    is a (poorly localized) match, 1.1 m a miss and a false positive."""
    gt = np.array([[0.0, 0.0]])
    for d, mota in ((0.9, 1.0), (1.1, -1.0)):
        steps = [Timestep(np.array([1]), np.array([7]), distance_similarity(gt, np.array([[d, 0.0]])))]
        score = evaluate({"world": steps})["world"]
        assert score["mota"] == mota, d
    assert math.isclose(distance_similarity(gt, np.array([[0.5, 0.0]]))[0, 0], 0.75)


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("tracks=missing", "invalid tracks='missing'.*no such file"),
        ("box=centre", "invalid box='centre'.*known: visible, amodal"),
        ("zero_distance_m=0", "invalid zero_distance_m=0.*metres"),
        ("classes=[spaceship]", "invalid classes=.*known:"),
        ("colour=red", "unknown tracking option 'colour'"),
    ],
)
def test_bad_options_are_refused(made: Path, tmp_path: Path, option: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        replay_main(
            [str(made / "run"), "--out", str(tmp_path / "out"), "--algorithms", "tracking", "--set", option]
        )
    assert not (tmp_path / "out").exists()


def test_bad_tracks_one_line_exit_2_nothing_written(made: Path, tmp_path: Path) -> None:
    rows = _mot_rows(made)
    late = {c: [list(r) for r in rs] for c, rs in rows.items()}
    late["161"].append(["999", "1", "1", "1", "5", "5", "1", "1", "1"])
    letters = {c: [list(r) for r in rs] for c, rs in rows.items()}
    letters["160"][0][4] = "wide"
    twice = {c: [list(r) for r in rs] for c, rs in rows.items()}
    twice["160"].append(list(twice["160"][0]))
    few = {"160": rows["160"]}
    fraction = {c: [list(r) for r in rs] for c, rs in rows.items()}
    fraction["161"][0][1] = "1.5"
    aicity = tmp_path / "aicity.txt"
    aicity.write_text("163 1 0 1 1 5 5 0.0 0.0\n")
    cases = {
        "late": ("frame=999", "frames 1..", "number frames from 1"),
        "letters": ("width='wide'", "not a finite number", "fix the row"),
        "twice": ("duplicate tracker id", "sequence camera_160", "its own id"),
        "few": ("missing tracks file", "camera_161.txt", "write an empty file"),
        "fraction": ("invalid id=1.5", "camera_161.txt line 1", "whole-number ids"),
    }
    for name, tracks in (
        ("late", late),
        ("letters", letters),
        ("twice", twice),
        ("few", few),
        ("fraction", fraction),
    ):
        folder = _tracker(tmp_path / "t", name, tracks)
        out = tmp_path / f"out_{name}"
        proc = run_cli(
            str(made / "run"), "--out", str(out), "--algorithms", "tracking", "--set", f"tracks={folder}",
            module="simlan_data.replay",
        )  # fmt: skip
        assert proc.returncode == 2, (name, proc.stderr)
        assert proc.stderr.strip().count("\n") == 0 and proc.stderr.startswith("error: "), proc.stderr
        assert all(part in proc.stderr for part in cases[name]), (name, proc.stderr)
        assert not out.exists()
    proc = run_cli(
        str(made / "run"), "--out", str(tmp_path / "out_ai"), "--algorithms", "tracking",
        "--set", f"tracks={aicity}", module="simlan_data.replay",
    )  # fmt: skip
    assert proc.returncode == 2 and "invalid camera_id='163'" in proc.stderr and "line 1" in proc.stderr
    assert not (tmp_path / "out_ai").exists()


def test_without_trackeval_the_metrics_name_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "trackeval", None)  # (as if not installed: the import fails)
    with pytest.raises(ConfigError, match=r'TrackEval is not installed.*pip install -e "\.\[tracking\]"'):
        evaluate({"world": []})
