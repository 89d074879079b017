"""The camera stage after rendering: what a real camera makes of the ideal render (issue 24).

Per camera, seeded by (run seed, camera id) through ``seeding.run_rng`` (one stream per effect, so
turning one effect on or off leaves the others' draws alone):

- **drift**: the true camera pose is the believed (recorded) one moved by a small random rotation
  about the camera centre and a translation (``DriftConfig``); the renderer draws from the true
  pose, everything recorded and every algorithm keeps the believed one;
- **timing**: a constant clock offset per camera and a jitter per frame on the stamp the camera
  writes (the header stamp: when the camera *says* it exposed); a frame is lost with
  ``drop_rate`` (nothing recorded, nothing reaches an algorithm); a free-running camera exposes
  a constant phase before the tick that delivers its frame, and each frame travels a transport
  delay: the frame shows the scene ``lag_s()`` before it arrives (``sim/exposures.py``);
- **photometric**: ``imaging.sensor_model.SensorModel`` on the colour image (noise, gain,
  exposure, vignetting, quantization).

What was done is one ``simlan_msgs/CameraEffects`` per camera frame on ``/camera_<id>/effects``
(recorded for dropped frames too): the true exposure time, the stamp written, the noise field
used, exposure and gain, the true pose. Replay reads the stamps back from the image headers, so it
gives the algorithms what the live run gave them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from simlan_data.config.sensors import DriftConfig, PhotometricConfig, SensorsConfig
from simlan_data.geometry.camera import CameraModel
from simlan_data.geometry.transforms import Transform, quat_from_rpy
from simlan_data.imaging.sensor_model import NoiseBank, PhotometricParams, SensorModel, linear_levels
from simlan_data.seeding import run_rng
from simlan_data.sim.rendering import CameraImages


def drifted(camera: CameraModel, drift: DriftConfig, seed: int) -> CameraModel:
    """``camera`` as it truly hangs after a bump: rotated about its centre and moved (map frame)."""
    if not drift.enabled or (drift.position_m == 0.0 and drift.rotation_deg == 0.0):
        return camera
    rng = run_rng(seed, "camera_drift", camera.camera_id)
    rpy = np.radians(rng.normal(0.0, drift.rotation_deg, 3))
    shift = rng.normal(0.0, drift.position_m, 3)
    world_from_cam = camera.world_from_camera
    centre = world_from_cam.translation
    bump = Transform.from_quat(np.zeros(3), quat_from_rpy(*rpy))  # about the camera centre, map axes
    true_world_from_cam = Transform(bump.rotation @ world_from_cam.rotation, centre + shift, None)
    return replace(camera, camera_from_world=true_world_from_cam.inverse())


def camera_sensors(
    cfg: SensorsConfig, seed: int, cameras: list[CameraModel], true_cameras: list[CameraModel]
) -> list[CameraSensor]:
    """The camera stage of every camera of a run (``cameras`` as believed, ``true_cameras`` as
    the renderers draw them: ``drifted``); cameras of one image size share a noise bank (twice the
    fields one camera uses: the draw is paid once per run, not per camera)."""
    banks: dict[tuple[int, int], NoiseBank] = {}
    phases = cfg.photometric.noise_phases
    out = []
    for cam, true_cam in zip(cameras, true_cameras, strict=True):
        bank = None
        if cfg.photometric.enabled and phases > 0:
            size = (cam.height, cam.width)
            if size not in banks:
                rng = run_rng(seed, "camera_noise_bank", f"{cam.width}x{cam.height}")
                banks[size] = NoiseBank(rng, (cam.height, cam.width, 3), fields=2 * phases)
            bank = banks[size]
        out.append(CameraSensor(cfg, seed, cam, true_cam, bank))
    return out


class AutoExposure:
    """A camera's exposure program: keep the image as bright as at its first frame, exposure
    first (up to ``max_exposure_scale``), then gain (up to ``max_gain``), as industrial cameras do.

    The camera meters its own image: the mean linear level of the render (every 8th pixel) times
    the light, exposure and gain. Each frame it corrects ``ae_step`` of the error in stops when the
    error exceeds ``ae_deadband`` (so a steady scene keeps its settings and the sensor model its
    cache). An unchanged render of the frame after the last one metered keeps its level (the
    metering, 0.3 ms a frame in a run, is skipped; most frames of a ceiling camera are unchanged).
    """

    def __init__(self, cfg: PhotometricConfig) -> None:
        self.cfg = cfg
        self.exposure, self.gain = cfg.exposure_scale, cfg.gain
        self.target: float | None = None
        self._linear = linear_levels(cfg.gamma).astype(np.float32)
        self._metered: tuple[int, float] | None = None  # (frame index, the render's level)

    def settings(
        self, rgb: NDArray[np.uint8], light: float, *, frame_index: int | None = None, changed: bool = True
    ) -> tuple[float, float]:
        """(exposure_scale, gain) for this frame, after metering ``rgb`` under ``light``
        (``changed=False``: ``rgb`` is the render of the previous frame ``frame_index - 1`` again)."""
        cfg = self.cfg
        if not cfg.auto_exposure:  # fixed settings: nothing to meter
            return self.exposure, self.gain
        level = self._render_level(rgb, frame_index, changed) * light * self.exposure * self.gain
        if self.target is None:
            self.target = level
            return self.exposure, self.gain
        if level <= 0:
            return self.exposure, self.gain
        error = self.target / level
        if abs(error - 1.0) <= cfg.ae_deadband:
            return self.exposure, self.gain
        total = self.exposure * self.gain * error**cfg.ae_step
        low = cfg.exposure_scale / cfg.max_exposure_scale
        self.exposure = float(np.clip(total, low, cfg.max_exposure_scale))
        self.gain = float(np.clip(total / self.exposure, 1.0, cfg.max_gain))
        return self.exposure, self.gain

    def _render_level(self, rgb: NDArray[np.uint8], frame_index: int | None, changed: bool) -> float:
        """The render's mean linear level, metered again unless the render is the last one's."""
        last = self._metered
        if changed or frame_index is None or last is None or last[0] != frame_index - 1:
            level = float(self._linear[rgb[::8, ::8]].mean())
        else:
            level = last[1]
        self._metered = None if frame_index is None else (frame_index, level)
        return level


@dataclass(frozen=True)
class Capture:
    """One camera frame after the camera stage."""

    images: CameraImages  # what the camera delivers (the colour image with the sensor's effects)
    stamp_ns: int  # simulated time the camera writes in the header (its clock)
    dropped: bool  # lost: nothing recorded, no algorithm sees it
    noise_phase: int  # which pre-drawn noise field the colour image carries (-1: none)
    exposure_scale: float  # the camera's exposure time, relative to the reference
    gain: float
    light: float  # the scene's light relative to the rendered (sensors.photometric.lighting)
    exposed_ns: int  # simulated time its exposure truly ended (the tick less phase and delay)
    subframes: int = 1  # renders averaged into the image (motion blur, rolling shutter)


class CameraSensor:
    """The camera stage of one camera (``capture`` once per rendered frame, in frame order)."""

    def __init__(
        self,
        cfg: SensorsConfig,
        seed: int,
        believed: CameraModel,
        true_camera: CameraModel,
        bank: NoiseBank | None = None,
    ) -> None:
        cid = believed.camera_id
        self.cfg, self.believed, self.true_camera = cfg, believed, true_camera
        p, t = cfg.photometric, cfg.timing
        self.model: SensorModel | None = None
        if p.enabled:
            params = PhotometricParams(
                full_well_e=p.full_well_e,
                read_noise_e=p.read_noise_e,
                gain=p.gain,
                exposure_scale=p.exposure_scale,
                vignetting=p.vignetting,
                adc_bits=p.adc_bits,
                gamma=p.gamma,
                noise_phases=p.noise_phases,
            )
            rng = run_rng(seed, "camera_noise", cid)
            self.model = SensorModel(params, self.true_camera, rng, bank=bank)
        self.exposure = AutoExposure(p)
        self._settings: tuple[float, float] | None = None
        self.offset_ns = 0
        if t.enabled and t.clock_offset_s > 0:
            self.offset_ns = round(
                float(run_rng(seed, "camera_clock", cid).normal(0.0, t.clock_offset_s)) * 1e9
            )
        self._frames = run_rng(seed, "camera_frames", cid)  # jitter and drops, one draw of each per frame
        self.phase_s = 0.0  # a free-running camera exposes this long before the tick (constant)
        if t.enabled and t.exposure_spread_s > 0:
            self.phase_s = float(run_rng(seed, "camera_phase", cid).uniform(0.0, t.exposure_spread_s))
        self._delays = run_rng(seed, "camera_delay", cid)  # transport delay, one draw per frame

    def lag_s(self) -> float:
        """How long before the tick the next frame's exposure ended: the camera's phase plus this
        frame's transport delay (call once per frame, before rendering it)."""
        t = self.cfg.timing
        if not self.cfg.lagged:
            return 0.0
        delay = t.delay_s + float(self._delays.normal(0.0, 1.0)) * t.delay_jitter_s
        return self.phase_s + max(0.0, delay)

    def exposure_time_s(self) -> float:
        """The exposure time of the next frame (``sensors.shutter.exposure_s`` x auto-exposure)."""
        return self.cfg.shutter.exposure_s * self.exposure.exposure

    def capture(
        self, t_ns: int, frame_index: int, images: CameraImages, *, subframes: int = 1, lag_ns: int = 0
    ) -> Capture:
        """The frame delivered at the tick ``t_ns``, whose exposure ended ``lag_ns`` before it."""
        t, p = self.cfg.timing, self.cfg.photometric
        jitter, lost = self._frames.normal(0.0, 1.0), self._frames.random()
        exposed = t_ns - lag_ns
        stamp = exposed
        dropped = False
        if t.enabled:
            stamp = exposed + self.offset_ns + round(jitter * t.clock_jitter_s * 1e9)
            dropped = bool(lost < t.drop_rate)
        phase, exposure, gain = -1, p.exposure_scale, p.gain
        light = p.light_at(exposed / 1e9) if p.enabled else 1.0
        if self.model is not None and images.rgb is not None and not dropped:
            exposure, gain = self.exposure.settings(
                images.rgb, light, frame_index=frame_index, changed=images.changed
            )
            rgb = self.model.apply(
                images.rgb, frame_index, exposure_scale=exposure * light, gain=gain, changed=images.changed
            )
            phase = self.model.phase(frame_index)
            # ``changed`` stays the render's: an unchanged scene in the same noise phase and
            # settings gives the same image, so the recorder reuses that phase's encoding (and
            # depth, labels as ever); new settings change every phase's image
            now = (exposure * light, gain)
            changed = images.changed or (self._settings is not None and self._settings != now)
            self._settings = now
            images = replace(images, rgb=rgb, changed=changed)
        return Capture(images, stamp, dropped, phase, exposure, gain, light, exposed, subframes)
