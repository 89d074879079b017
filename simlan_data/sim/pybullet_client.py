"""Connect to PyBullet headless, with the EGL renderer where it loads, quietly."""

from __future__ import annotations

import importlib.util
import os
from dataclasses import dataclass

from simlan_data.errors import ConfigError
from simlan_data.world._pybullet import pb, silence_c_output

RENDER_BACKENDS = ("auto", "egl", "tiny")


@dataclass
class Client:
    """A PyBullet physics client and the renderer that actually loaded."""

    id: int
    backend: str  # "egl" or "tiny"
    egl_plugin: int = -1

    def disconnect(self) -> None:
        if self.id >= 0:
            with silence_c_output(stderr=True):
                if self.egl_plugin >= 0:
                    pb.unloadPlugin(self.egl_plugin, physicsClientId=self.id)
                pb.disconnect(self.id)
            self.id = -1


def egl_plugin_path() -> str | None:
    spec = importlib.util.find_spec("eglRenderer")
    return spec.origin if spec and spec.origin else None


def connect(backend: str = "auto", *, software_gl_threads: int = 1) -> Client:
    """Start a DIRECT client; load the EGL renderer for ``egl``/``auto`` (before any body exists).

    ``software_gl_threads`` sets Mesa llvmpipe's rasterizer threads (``LP_NUM_THREADS``, unless
    the environment sets it): measured on 2 cores, one thread leaves the other core to the image
    encoders and records the default run faster; it does not matter with a GPU.

    Raises:
        ConfigError: ``backend`` is unknown, or ``egl`` was asked for and does not load.
    """
    if backend not in RENDER_BACKENDS:
        raise ConfigError(
            f"unknown render.backend '{backend}'",
            "config",
            f"expected one of {', '.join(RENDER_BACKENDS)}",
            "use render.backend=auto",
        )
    if software_gl_threads > 0:
        os.environ.setdefault("LP_NUM_THREADS", str(software_gl_threads))
    with silence_c_output(stderr=True):
        cid = pb.connect(pb.DIRECT)
        plugin = -1
        if backend in ("auto", "egl"):
            path = egl_plugin_path()
            if path is not None and not os.environ.get("SIMLAN_DISABLE_EGL"):
                plugin = pb.loadPlugin(path, "_eglRendererPlugin", physicsClientId=cid)
    if backend == "egl" and plugin < 0:
        pb.disconnect(cid)
        raise ConfigError(
            "EGL renderer unavailable",
            "render.backend=egl",
            "PyBullet's eglRenderer plugin did not load (no EGL/Mesa libraries?)",
            "install Mesa's EGL (libegl-mesa0, libgl1-mesa-dri) or use render.backend=tiny",
        )
    return Client(cid, "egl" if plugin >= 0 else "tiny", plugin)
