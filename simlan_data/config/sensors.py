"""The ``sensors`` section: cameras as imperfect as real ones (issue 24; docs/sensors.md).

Everything is off by default (``sensors=ideal``); ``sensors=realistic`` turns every effect on at
the defaults of a real camera. Each effect is seeded by (run seed, camera id) and what it did is
recorded per frame on ``/camera_<id>/effects``:

- ``photometric``: shot noise, read noise, ADC quantization, analog gain, exposure, vignetting
  (``imaging/sensor_model.py``), applied to the rendered colour image before it is encoded;
- ``timing``: each camera's clock offset (constant), per-frame stamp jitter and frame drops; the
  instant it exposes (a constant phase per camera: free-running cameras) and the transport delay
  to the algorithms; the header stamp is when the camera says it exposed, the effects topic says
  when it did;
- ``drift``: the camera was bumped: the image is rendered from a perturbed true pose while the
  recorded ``camera_info`` and ``/tf_static`` (and what the algorithms are given) stay the believed
  calibration.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from simlan_data.errors import ConfigError

MAX_LAG_S = 1.0  # how far back a frame may show the scene (the frames the simulation holds back)


def _at_least(key: str, value: float, low: float, fix: str) -> None:
    if not value >= low:
        raise ConfigError.invalid(key, value, f"must be >= {low:g}", fix)


@dataclass
class PhotometricConfig:
    """Sensor noise and exposure (``imaging/sensor_model.py``); defaults of ``sensors=realistic`` there."""

    enabled: bool = False
    full_well_e: float = 10000.0  # electrons at saturation (value 255 at gain 1, reference exposure)
    read_noise_e: float = 2.5  # read noise, electrons RMS
    gain: float = 1.0  # analog gain (1 = base ISO); brightness x gain, noise relative to signal x sqrt(gain)
    exposure_scale: float = 1.0  # exposure time relative to the one at which the render's values hold
    vignetting: float = 0.0  # illumination lost at the image corner (0..1), cos^4 falloff
    adc_bits: int = 12  # raw quantization before the 8-bit output
    gamma: float = 2.2  # the render is display-referred: noise is added in linear (electron) space
    noise_phases: int = 8  # pre-drawn noise fields cycled frame by frame (0: fresh each frame, full cost)
    lighting: list[list[float]] = field(default_factory=list)  # [[t_s, scale], ...]: from t_s on the
    # scene's light is scale x the rendered (a cloud over the skylights, lights switched off)
    auto_exposure: bool = False  # the camera keeps its image as bright as at its first frame
    max_exposure_scale: float = 4.0  # auto-exposure lengthens the exposure up to this (motion blur's limit)
    max_gain: float = 16.0  # then raises the gain up to this (noise grows with it)
    ae_step: float = 0.5  # share of the brightness error (in stops) corrected per frame
    ae_deadband: float = 0.1  # brightness error (relative) it tolerates before acting

    def __post_init__(self) -> None:
        for key in ("full_well_e", "gain", "exposure_scale", "gamma"):
            value = getattr(self, key)
            if not value > 0:
                raise ConfigError.invalid(
                    f"sensors.photometric.{key}", value, "must be > 0", "use the default"
                )
        _at_least("sensors.photometric.read_noise_e", self.read_noise_e, 0.0, "use 2.5")
        if not 0.0 <= self.vignetting < 1.0:
            raise ConfigError.invalid(
                "sensors.photometric.vignetting",
                self.vignetting,
                "must be within 0..1 (1: a black corner)",
                "use 0.3",
            )
        if not 8 <= self.adc_bits <= 16:
            raise ConfigError.invalid(
                "sensors.photometric.adc_bits", self.adc_bits, "must be within 8..16", "use 12"
            )
        _at_least(
            "sensors.photometric.noise_phases", self.noise_phases, 0, "use 8 (0: fresh noise every frame)"
        )
        _at_least("sensors.photometric.max_exposure_scale", self.max_exposure_scale, 1.0, "use 4.0")
        _at_least("sensors.photometric.max_gain", self.max_gain, 1.0, "use 16.0")
        if not 0.0 < self.ae_step <= 1.0:
            raise ConfigError.invalid(
                "sensors.photometric.ae_step", self.ae_step, "must be within (0, 1]", "use 0.5"
            )
        _at_least("sensors.photometric.ae_deadband", self.ae_deadband, 0.0, "use 0.1")
        times = []
        for entry in self.lighting:
            if len(entry) != 2 or not entry[0] >= 0 or not entry[1] > 0:
                raise ConfigError.invalid(
                    "sensors.photometric.lighting", self.lighting, f"{list(entry)} is not [t_s >= 0, scale > 0]",
                    "e.g. sensors.photometric.lighting=[[10.0,0.25]]",
                )  # fmt: skip
            times.append(entry[0])
        if times != sorted(times):
            raise ConfigError.invalid(
                "sensors.photometric.lighting",
                self.lighting,
                "times must increase",
                "list the changes in time order",
            )

    def light_at(self, t_s: float) -> float:
        """The scene's light at ``t_s`` relative to the rendered (1 before the first change)."""
        scale = 1.0
        for start, value in self.lighting:
            if t_s >= start:
                scale = value
        return scale


@dataclass
class TimingConfig:
    """Camera clocks and frame delivery."""

    enabled: bool = False
    clock_offset_s: float = (
        0.0  # standard deviation of each camera's constant clock offset (seeded per camera)
    )
    clock_jitter_s: float = 0.0  # standard deviation of the per-frame stamp jitter
    drop_rate: float = 0.0  # probability that a frame is lost (not recorded, never reaches an algorithm)
    exposure_spread_s: float = 0.0  # free-running cameras: each exposes a constant phase drawn in
    # [0, this) before the tick that delivers its frame (0: hardware-triggered, all at once)
    delay_s: float = 0.0  # transport: exposure to arrival at the algorithms (network, decode)
    delay_jitter_s: float = 0.0  # standard deviation of the per-frame transport delay (clipped at 0)

    def __post_init__(self) -> None:
        _at_least("sensors.timing.clock_offset_s", self.clock_offset_s, 0.0, "use 0.005")
        _at_least("sensors.timing.clock_jitter_s", self.clock_jitter_s, 0.0, "use 0.001")
        _at_least("sensors.timing.exposure_spread_s", self.exposure_spread_s, 0.0, "use 0 or up to 1/fps")
        _at_least("sensors.timing.delay_s", self.delay_s, 0.0, "use 0.03")
        _at_least("sensors.timing.delay_jitter_s", self.delay_jitter_s, 0.0, "use 0.005")
        if self.max_lag_s > MAX_LAG_S:
            raise ConfigError.invalid(
                "sensors.timing",
                f"exposure_spread_s={self.exposure_spread_s}, delay_s={self.delay_s}, "
                f"delay_jitter_s={self.delay_jitter_s}",
                f"a frame may show the scene at most {MAX_LAG_S:g} s before it arrives "
                "(spread + delay + 4 x jitter)",
                "use exposure_spread_s <= 0.2 and delay_s <= 0.5",
            )
        if not 0.0 <= self.drop_rate < 1.0:
            raise ConfigError.invalid(
                "sensors.timing.drop_rate",
                self.drop_rate,
                "must be within 0..1 (1 would drop every frame)",
                "use 0.01",
            )

    @property
    def max_lag_s(self) -> float:
        """The longest a frame may show the scene before it arrives: phase + delay + 4 x jitter
        (a larger jitter draw is clipped to it)."""
        return self.exposure_spread_s + self.delay_s + 4 * self.delay_jitter_s


@dataclass
class DriftConfig:
    """A bumped camera: the true pose differs from the calibration the recording and algorithms hold."""

    enabled: bool = False
    position_m: float = 0.0  # standard deviation per axis of the true camera position's offset
    rotation_deg: float = 0.0  # standard deviation per axis of the true camera orientation's offset

    def __post_init__(self) -> None:
        _at_least("sensors.drift.position_m", self.position_m, 0.0, "use 0.003")
        _at_least("sensors.drift.rotation_deg", self.rotation_deg, 0.0, "use 0.2")
        if self.position_m > 1.0 or self.rotation_deg > 30.0:
            raise ConfigError.invalid(
                "sensors.drift",
                f"position_m={self.position_m}, rotation_deg={self.rotation_deg}",
                "a drift is a bump (a few mm, tenths of a degree), at most 1 m and 30 degrees",
                "use position_m=0.003 rotation_deg=0.2",
            )


@dataclass
class ShutterConfig:
    """Exposure over time: motion blur and rolling shutter, from sub-frames rendered at the agents'
    poses within the exposure (``sim/shutter.py``)."""

    enabled: bool = False
    exposure_s: float = 0.005  # exposure time at exposure_scale 1 (auto-exposure lengthens it)
    line_time_s: float = (
        0.0  # rolling shutter: delay between the starts of two image rows (0: global shutter)
    )
    px_per_sample: float = 0.5  # one sub-frame per this much image motion (pixels) over the exposure window
    max_samples: int = 8  # at most this many sub-frames per camera tick

    def __post_init__(self) -> None:
        _at_least("sensors.shutter.exposure_s", self.exposure_s, 0.0, "use 0.005")
        if self.exposure_s > 0.2:
            raise ConfigError.invalid(
                "sensors.shutter.exposure_s", self.exposure_s, "at most 0.2 s (a 5 Hz camera)", "use 0.005"
            )
        _at_least(
            "sensors.shutter.line_time_s",
            self.line_time_s,
            0.0,
            "use 0 (global) or 6e-5 (a 4K rolling shutter, per rendered row)",
        )
        if not self.px_per_sample > 0:
            raise ConfigError.invalid(
                "sensors.shutter.px_per_sample", self.px_per_sample, "must be > 0", "use 0.5"
            )
        if not 1 <= self.max_samples <= 64:
            raise ConfigError.invalid(
                "sensors.shutter.max_samples", self.max_samples, "must be within 1..64", "use 8"
            )


@dataclass
class SensorsConfig:
    """Realistic cameras: ``sensors=realistic`` (every effect on) or ``sensors=ideal`` (none, the default)."""

    name: str = "ideal"
    photometric: PhotometricConfig = field(default_factory=PhotometricConfig)
    timing: TimingConfig = field(default_factory=TimingConfig)
    drift: DriftConfig = field(default_factory=DriftConfig)
    shutter: ShutterConfig = field(default_factory=ShutterConfig)

    @property
    def lagged(self) -> bool:
        """Frames may show the scene before the tick that delivers them (spread or delay)."""
        return self.timing.enabled and self.timing.max_lag_s > 0

    @property
    def active(self) -> bool:
        return self.photometric.enabled or self.timing.enabled or self.drift.enabled or self.shutter.enabled
