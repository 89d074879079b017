"""A two-job sweep through Hydra's Ray launcher on a local Ray cluster started by the test.

The cluster is a real one (``ray start --head --node-ip-address=127.0.0.1``, as on a cluster's
head node); the sweep connects to it by address through ``hydra/launcher=ray_cluster``, every
job runs as a Ray task in a Ray worker process and writes its own run directory, and the one
aggregation step (the Hydra callback, where the sweep was started) reads every metrics.json.
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import polars as pl
import pytest

from conftest import run_cli

pytestmark = pytest.mark.slow
RAY = Path(sys.executable).with_name("ray")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# Ray 2.60 turns token authentication on once ~/.ray/auth_token exists (any local ray.init, e.g.
# posemap.pool=ray, writes one), and then a sweep connecting by address was refused ("InvalidAuthToken":
# the slow suite failed whenever the posemap pool test ran first). The cluster and the sweep get a
# token of their own, as a secured cluster does, whatever the user's home holds.
RAY_AUTH = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(16)}


@pytest.fixture
def ray_cluster() -> Iterator[str]:
    """A one-node Ray cluster on this machine for the test; stopped (and only it) afterwards."""
    if not RAY.exists():
        pytest.fail(f"{RAY} missing: install the ray extra (pip install -e '.[test]' includes it)")
    port = _free_port()
    # a short temp dir of its own: Ray's socket paths must stay under the AF_UNIX length limit
    temp_dir = tempfile.mkdtemp(prefix="ray_", dir="/tmp")
    proc = subprocess.Popen(
        [
            str(RAY),
            "start",
            "--head",
            "--block",  # stays in the foreground: stopping this process stops the cluster
            "--node-ip-address=127.0.0.1",
            f"--port={port}",
            f"--ray-client-server-port={_free_port()}",
            f"--dashboard-agent-listen-port={_free_port()}",
            "--num-cpus=2",
            "--include-dashboard=false",
            "--disable-usage-stats",
            f"--temp-dir={temp_dir}",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, **RAY_AUTH},
        start_new_session=True,  # its own process group: nothing else is signalled at the end
    )
    try:
        assert proc.stdout is not None
        deadline = time.monotonic() + 120
        for line in proc.stdout:
            if "block forever" in line:
                break
            if time.monotonic() > deadline:
                pytest.fail("the Ray head node did not start within 120 s")
        else:
            pytest.fail(f"ray start exited with {proc.wait()}")
        yield f"127.0.0.1:{port}"
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        shutil.rmtree(temp_dir, ignore_errors=True)


def test_two_job_sweep_on_a_local_ray_cluster(ray_cluster: str, tmp_path: Path) -> None:
    sweep = tmp_path / "sweep"
    proc = run_cli(
        "-m",
        "hydra/launcher=ray_cluster",
        f"hydra.launcher.ray.init.address={ray_cluster}",
        "seed=0,1",
        "duration_s=0.4",
        "cameras=single",
        "cameras.width=320",
        "cameras.height=180",
        "world.fidelity=empty",
        "world.settle_s=0",
        "progress=false",
        f"hydra.sweep.dir={sweep}",
        env=RAY_AUTH,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Connected to Ray cluster" in proc.stderr  # a Ray cluster, not a local process pool
    table = pl.read_parquet(sweep / "sweep_metrics.parquet")
    assert table["override.seed"].to_list() == [0, 1]
    assert table["status"].to_list() == ["ok", "ok"]
    assert table["job.opencv_threads"].to_list() == [1.0, 1.0]  # one core per Ray task
    assert table["job.encode_threads"].to_list() == [0.0, 0.0]  # ... and no encoder threads
    assert all(frames > 0 for frames in table["sim.camera_frames"].to_list())
    for job in ("0", "1"):
        assert (sweep / job / "recording" / "metadata.yaml").is_file()
        assert (sweep / job / "metrics.json").is_file()
    # the jobs ran in Ray worker processes, not in the process that started the sweep
    assert "(_run_job pid=" in proc.stdout + proc.stderr
