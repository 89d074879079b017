"""Photometric sensor model: what a real camera makes of the ideal render (issue 24).

The renderer delivers display-referred 8-bit RGB: the light a perfect camera would report. A real
sensor counts electrons, adds noise, digitizes them and gamma-encodes the result. Per pixel and
channel, for a render value ``rgb`` (0..255):

1. linearize: ``L = (rgb / 255) ** gamma`` (a 256-entry table);
2. electrons: ``S = L * full_well_e * exposure_scale * V(pixel)``, with ``V`` the vignetting map
   (:func:`vignetting_map`: ``cos^4`` of each pixel's field angle through the real, distorted lens
   model, scaled so the image corner keeps ``1 - vignetting`` of the centre);
3. noise: photon shot noise, Poisson(S), and read noise, N(0, read_noise_e^2). The Poisson draw
   is approximated by a Gaussian of variance ``S`` (the same mean and variance; its shape differs
   noticeably only below a few electrons, where read noise dominates anyway), so
   ``S_noisy = S + sqrt(S + read_noise_e^2) * z`` with ``z`` standard normal;
4. ADC: ``DN = clip(S_noisy * gain / full_well_e, 0, 1)`` quantized to ``adc_bits``;
5. output: ``round(255 * DN ** (1 / gamma))`` as uint8 (a ``2**adc_bits``-entry table).

At ``gain = 1`` and the reference exposure the render's white is exactly the full well: without
noise it stays 255; with noise about half its pixels fall a code or two below (a pixel exactly at
saturation is noisy; only light above it clips cleanly, e.g. ``gain > 1`` or ``exposure_scale >
1``). Trading exposure for gain (``exposure_scale = 1/4, gain = 4``) keeps the brightness and
doubles the relative noise, as a real auto-exposure does in low light.

The arithmetic is float32 throughout (a DN of 4095 is exact in float32), done with OpenCV's
vectorized element-wise functions and lookup tables; no float64 image is ever formed.

Cost: noise phases and a row cache
----------------------------------
Drawing 1.5 million Gaussian numbers per 960x540 frame costs more than the whole rest of the model,
so ``noise_phases`` (default 8) noise fields are drawn once, at construction, from the generator the
caller passes (``run_rng(seed, "camera_noise", camera_id)``), and frame ``i`` uses field
``i % noise_phases``. The fields are stored as int8 (``z * 24``, clipped at +-5.3 sigma: the stored
field's variance is within 0.02 % of 1), 1.5 MB per field at 960x540.

The trade-off: the noise repeats every ``noise_phases`` frames. A pixel's noise over up to
``noise_phases`` consecutive frames is independent, but statistics over more frames than that
(temporal averaging, a background model over a long window) see the same noise values again and
underestimate the noise by up to ``sqrt(frames / noise_phases)``. ``noise_phases = 0`` draws fresh
noise every frame (from a generator keyed by the frame index, so still a pure function of seed
and frame) at the full cost, with no caching.

Because a phase's noise is fixed, a pixel whose input is unchanged since that phase last ran gives
the same output again. Per phase the model keeps its last output and a mask of the blocks (one
row by ``CHUNK_PX`` columns) that changed since: the input is compared with the previous frame's
as 64-bit words, and each change marks its blocks dirty in every phase. A phase recomputes one
rectangle per run of dirty rows (the dirty blocks' columns; runs closer than ``MERGE_ROWS`` rows
joined) and reuses the rest. This is exact: the output equals what a fresh model gives for the
same frame index (a pixel recomputed although clean gives its old value again). A moving robot
changes about half a percent of a ceiling camera's pixels per frame (0.5-0.7 % over the 8 frames
a phase accumulates, against 4.5 % for whole rows: the default run's cameras). The caller may
say a frame is unchanged (``apply(changed=False)``: the render reused, as the recorder is told):
then the compare is skipped too, unless a frame index was skipped since the last call (a lost
frame's change would be missed). A change of exposure or gain recomputes the whole frame.

The output is read-only and shared: a phase whose image did not change returns the same array
again (no copy); a phase that recomputes anything writes into a copy while anyone still holds
the image it handed out earlier (perhaps being encoded on another thread: copy on write, by
CPython's reference count), into that image itself once nobody does; an image handed out never
changes.
Memory per 960x540 camera: 1.5 MB of noise and 1.5 MB of output per phase, the last input and,
with vignetting, a 6 MB float32 map per channel (about 32 MB with 8 phases); plus 25 MB of work
buffers per thread that applies models, shared by all cameras of that thread (fresh arrays per
step cost more in page faults than the arithmetic).

Defaults (:func:`realistic_defaults`)
-------------------------------------
SIMLAN's ceiling cameras are 4K fisheye units. The figures are typical EMVA 1288 values of the
Sony Pregius/STARVIS class of CMOS sensors (2-3.45 um pixels) used in 4K industrial and
surveillance cameras, as the camera makers publish them in their EMVA 1288 data sheets (FLIR
Blackfly S and Basler ace models with the IMX250/IMX267 3.45 um Pregius sensors list a saturation
capacity of about 10 ke- and a temporal dark noise of about 2-2.5 e-; smaller 2 um 4K pixels hold
less, about 5-8 ke-). They were not re-checked against a data sheet in this session; treat them as
typical values, not as a particular camera's measurement:

- ``full_well_e = 10000`` e- (saturation capacity), ``read_noise_e = 2.5`` e- (temporal dark
  noise), ``adc_bits = 12`` (the usual ADC depth of these sensors);
- ``vignetting = 0.3``: a wide-angle CCTV lens keeps roughly 60-80 % relative illumination at the
  image corner (lens makers' relative-illumination curves); 70 % is a middle value;
- ``gamma = 2.2`` (the sRGB-like transfer the render and the recorded JPEGs are in).

The figures are per sensor pixel. A 960x540 render standing for a 3840x2160 camera that bins or
downsamples 4x4 collects 16 pixels per rendered pixel: ``realistic_defaults(binning=16)`` scales
the full well by 16 and the read noise by 4 (quadrature sum); the default ``binning=1`` is the
noisier, conservative choice.
"""

from __future__ import annotations

import sys
import threading
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

NOISE_SCALE = 24.0  # int8 noise fields hold round(24 z): step 1/24 sigma, clipped at 127/24 = 5.3 sigma
VIGNETTING_GRID_PX = 8  # field angles on an 8-pixel grid, bilinear in between: within 0.003 of
# the exact map (0.002 on a 4-pixel grid), 3 ms a camera instead of 13
# change tracking: blocks of one row by CHUNK_PX columns (a multiple of 8: whole 64-bit words of
# RGB); dirty row runs less than MERGE_ROWS apart are recomputed as one rectangle (fewer calls)
CHUNK_PX = 64
MERGE_ROWS = 16


class LensCamera(Protocol):
    """What the model needs of a camera: ``simlan_data.geometry.camera.CameraModel`` is one.

    A protocol rather than an import: ``imaging`` and ``geometry`` are side-by-side layers that do
    not import each other (pyproject.toml, import-linter).
    """

    @property
    def camera_id(self) -> str: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    def pixel_rays(
        self, uv: ArrayLike, *, distorted: bool = True
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]: ...


@dataclass(frozen=True)
class PhotometricParams:
    """A sensor's photometric parameters (module docstring: the model and the defaults)."""

    full_well_e: float  # electrons at the sensor's saturation (255 at gain 1, reference exposure)
    read_noise_e: float  # read noise, electrons RMS
    gain: float = 1.0  # ISO-like analog gain: DN per electron = 255 / full_well_e * gain
    exposure_scale: float = 1.0  # exposure time relative to the render's reference exposure
    vignetting: float = 0.0  # relative illumination lost at the image corner (cos^4 falloff)
    adc_bits: int = 12  # quantization of the raw signal before the 8-bit output
    gamma: float = 2.2  # the render is display-referred: linearized with this, noise in electrons
    noise_phases: int = 8  # pre-drawn noise fields cycled frame by frame (0 = fresh each frame)
    noise: bool = True  # False: no shot or read noise (vignetting, exposure and ADC only)

    def __post_init__(self) -> None:
        checks = {
            "full_well_e must be > 0": self.full_well_e > 0,
            "read_noise_e must be >= 0": self.read_noise_e >= 0,
            "gain must be > 0": self.gain > 0,
            "exposure_scale must be > 0": self.exposure_scale > 0,
            "vignetting must be in [0, 1)": 0 <= self.vignetting < 1,
            "adc_bits must be in 1..16": 1 <= self.adc_bits <= 16,
            "gamma must be > 0": self.gamma > 0,
            "noise_phases must be >= 0": self.noise_phases >= 0,
        }
        bad = [what for what, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"PhotometricParams: {'; '.join(bad)}")


def realistic_defaults(binning: int = 1) -> PhotometricParams:
    """Typical EMVA 1288 figures of a 4K industrial/surveillance CMOS sensor (module docstring).

    ``binning``: sensor pixels averaged into one rendered pixel (16 for a 3840x2160 camera
    rendered at 960x540); the full well adds up, the read noise adds in quadrature.
    """
    if binning < 1:
        raise ValueError("binning must be >= 1")
    return PhotometricParams(
        full_well_e=10000.0 * binning,
        read_noise_e=2.5 * float(np.sqrt(binning)),
        vignetting=0.3,
        adc_bits=12,
        gamma=2.2,
    )


def vignetting_map(camera: LensCamera, vignetting: float) -> NDArray[np.float32]:
    """Relative illumination per pixel (H, W): 1 on the optical axis, ``1 - vignetting`` at the
    image's largest field angle, in between ``1 - vignetting * (1 - cos^4 t) / (1 - cos^4 t_max)``
    with ``t`` the pixel's field angle through the distorted lens model (``CameraModel.pixel_rays``).

    Pixels without a valid ray (the corners of a strongly distorted lens, black in the render) get
    ``1 - vignetting``, which is also the value at the valid region's rim, so the map is continuous.
    """
    h, w = camera.height, camera.width
    if vignetting == 0:
        return np.ones((h, w), np.float32)
    step = VIGNETTING_GRID_PX
    gh, gw = -(-h // step), -(-w // step)
    # grid cell centres, so that cv2.resize by ``step`` puts them back where they were sampled
    gu, gv = np.meshgrid(np.arange(gw) * step + (step - 1) / 2, np.arange(gh) * step + (step - 1) / 2)
    rays, ok = camera.pixel_rays(np.stack([gu.ravel(), gv.ravel()], axis=1))
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], np.float64)
    corner_rays, corner_ok = camera.pixel_rays(corners)
    cos4 = rays[:, 2] ** 4
    cos4_min = min(cos4[ok].min(initial=1.0), (corner_rays[corner_ok, 2] ** 4).min(initial=1.0))
    if cos4_min >= 1.0:
        raise ValueError(f"camera {camera.camera_id}: no pixel off the optical axis has a valid ray")
    loss = np.where(ok, (1.0 - cos4) / (1.0 - cos4_min), 1.0)
    grid = (1.0 - vignetting * np.clip(loss, 0.0, 1.0)).reshape(gh, gw).astype(np.float32)
    full = cv2.resize(grid, (gw * step, gh * step), interpolation=cv2.INTER_LINEAR)[:h, :w]
    return np.ascontiguousarray(np.clip(full, 1.0 - vignetting, 1.0), dtype=np.float32)


@dataclass
class _Phase:
    """The cache of one noise phase: its noise field, last output and rows changed since."""

    noise: NDArray[np.int8]
    dirty: NDArray[np.bool_]  # (rows, column chunks) whose input changed since the last output
    output: NDArray[np.uint8] | None = None  # read-only; replaced, never written, once handed out
    settings: tuple[float, float] | None = None  # (exposure_scale, gain) the output was made with


def linear_levels(gamma: float) -> NDArray[np.float64]:
    """The linear light of each 8-bit display-referred level: ``(level / 255) ** gamma``."""
    return (np.arange(256, dtype=np.float64) / 255.0) ** gamma


def draw_noise_field(rng: np.random.Generator, shape: tuple[int, ...]) -> NDArray[np.int8]:
    """A standard normal field stored as int8 (``NOISE_SCALE`` per sigma)."""
    z = rng.standard_normal(shape, dtype=np.float32)
    z *= NOISE_SCALE
    np.rint(z, out=z)
    np.clip(z, -127, 127, out=z)
    return z.astype(np.int8)


class NoiseBank:
    """Noise fields drawn once per run and shared by its cameras.

    Drawing the fields is most of a model's construction (about 20 ms per 960x540 field, 8 per
    camera: 1.8 s for the 11 GPSS cameras, a tenth of a 60 s run's wall time). A bank holds
    ``fields`` fields ``extra_rows`` taller than the images; each camera takes, from its own seeded
    stream, a random choice of them and a random row offset into each (views, no copies). So two
    cameras' noise at the same frame is either from different fields or the same field shifted by
    whole rows: independent per pixel, but a shifted copy. Nothing here reads across cameras' noise
    (every algorithm looks at one image at a time); an analysis that does should use one model
    per camera without a bank.
    """

    def __init__(
        self, rng: np.random.Generator, shape: tuple[int, ...], *, fields: int, extra_rows: int = 64
    ) -> None:
        self.shape, self.extra_rows = tuple(shape), extra_rows
        tall = (shape[0] + extra_rows, *shape[1:])
        self._fields = [draw_noise_field(rng, tall) for _ in range(fields)]

    def fields_for(
        self, rng: np.random.Generator, phases: int, shape: tuple[int, ...]
    ) -> list[NDArray[np.int8]]:
        """``phases`` fields for one camera (``rng``: the camera's own stream)."""
        if tuple(shape) != self.shape:
            raise ValueError(f"the bank's fields are {self.shape}, the camera's images {tuple(shape)}")
        if phases > len(self._fields):
            raise ValueError(f"the bank holds {len(self._fields)} fields, {phases} asked")
        order = rng.permutation(len(self._fields))[:phases]
        rows = rng.integers(0, self.extra_rows + 1, size=phases)
        return [self._fields[int(k)][int(r) : int(r) + shape[0]] for k, r in zip(order, rows, strict=True)]


class SensorModel:
    """The photometric sensor of one camera (module docstring: physics, cost, determinism)."""

    def __init__(
        self,
        params: PhotometricParams,
        camera: LensCamera,
        rng: np.random.Generator,
        *,
        bank: NoiseBank | None = None,
    ) -> None:
        """``bank``: take the noise fields from a bank shared by the run's cameras (``NoiseBank``)
        instead of drawing them (``rng`` then picks which fields and where)."""
        self.params = params
        self.shape = (camera.height, camera.width, 3)
        vmap = vignetting_map(camera, params.vignetting)
        self._vignetting: NDArray[np.float32] | None = None
        if params.vignetting > 0:  # per channel: cv2.multiply does not broadcast, numpy's is 6x slower
            self._vignetting = np.ascontiguousarray(np.repeat(vmap[..., None], 3, axis=2))
        self._qmax = float(2**params.adc_bits - 1)
        codes = np.arange(2**params.adc_bits, dtype=np.float64) / self._qmax
        self._out_lut = np.rint(255.0 * codes ** (1.0 / params.gamma)).astype(np.uint8)
        self._linear = linear_levels(params.gamma)
        fields = (
            bank.fields_for(rng, params.noise_phases, self.shape)
            if bank is not None
            else [draw_noise_field(rng, self.shape) for _ in range(params.noise_phases)]
        )
        chunks = -(-camera.width // CHUNK_PX)
        self._phases = [_Phase(field, np.ones((camera.height, chunks), bool)) for field in fields]
        self._fresh_key = int(rng.integers(2**63))  # noise_phases == 0: frame noise keyed by index
        self._last_input: NDArray[np.uint8] | None = None
        self._last_frame: int | None = None

    def phase(self, frame_index: int) -> int:
        """The noise field frame ``frame_index`` uses (-1 with fresh noise per frame)."""
        n = self.params.noise_phases
        return frame_index % n if n else -1

    def apply(
        self,
        rgb: NDArray[np.uint8],
        frame_index: int,
        *,
        exposure_scale: float | None = None,
        gain: float | None = None,
        changed: bool = True,
    ) -> NDArray[np.uint8]:
        """The image the sensor delivers for the ideal render ``rgb`` (H, W, 3) at frame ``frame_index``.

        ``changed=False``: ``rgb`` equals the previous call's input (the render was reused), so
        it is not compared again; trusted only when ``frame_index`` follows the previous call's.
        The result is read-only and may be the array an earlier call returned (module docstring).
        """
        rgb = np.ascontiguousarray(rgb)
        if rgb.shape != self.shape or rgb.dtype != np.uint8:
            raise ValueError(f"expected a uint8 image of shape {self.shape}, got {rgb.dtype} {rgb.shape}")
        settings = (
            float(self.params.exposure_scale if exposure_scale is None else exposure_scale),
            float(self.params.gain if gain is None else gain),
        )
        if settings[0] <= 0 or settings[1] <= 0:
            raise ValueError(f"exposure_scale and gain must be > 0, got {settings}")
        if not self._phases:
            z = np.random.default_rng([self._fresh_key, frame_index]).standard_normal(
                self.shape, dtype=np.float32
            )
            return self._render(rgb, self._vignetting, z, 1.0, settings)
        self._mark_changed(rgb, changed or self._last_frame != frame_index - 1)
        self._last_frame = frame_index
        phase = self._phases[self.phase(frame_index)]
        if phase.output is None or phase.settings != settings:
            phase.output = self._render(rgb, self._vignetting, phase.noise, 1 / NOISE_SCALE, settings)
        elif phase.dirty.any():
            phase.output = self._rerender(rgb, phase, settings)
        phase.output.flags.writeable = False
        phase.settings = settings
        phase.dirty[:] = False
        return phase.output

    def _rerender(
        self, rgb: NDArray[np.uint8], phase: _Phase, settings: tuple[float, float]
    ) -> NDArray[np.uint8]:
        """The phase's output with its dirty blocks recomputed from ``rgb``: in place if nobody
        else holds the image any more (CPython's reference count: the phase, ``out`` and the
        count's argument), else in a copy, so that an image handed out never changes."""
        out = phase.output
        assert out is not None
        if sys.getrefcount(out) > 3:
            out = out.copy()
        else:
            out.flags.writeable = True
        for r0, r1, u0, u1 in dirty_rects(phase.dirty, CHUNK_PX, self.shape[1]):
            vig = None if self._vignetting is None else self._vignetting[r0:r1, u0:u1]
            z = phase.noise[r0:r1, u0:u1]
            self._render(rgb[r0:r1, u0:u1], vig, z, 1 / NOISE_SCALE, settings, out=out[r0:r1, u0:u1])
        return out

    def _mark_changed(self, rgb: NDArray[np.uint8], compare: bool) -> None:
        """Mark the blocks that differ from the previous frame dirty in every phase; keep the
        input (``compare=False``: the caller vouches that nothing changed)."""
        if self._last_input is None:
            self._last_input = rgb.copy()
            changed = np.ones(self._phases[0].dirty.shape, bool)
        elif not compare:
            return
        else:
            changed = changed_blocks(self._last_input, rgb, CHUNK_PX)
            rows = changed.any(axis=1)
            if not rows.any():
                return
            self._last_input[rows] = rgb[rows]
        for phase in self._phases:
            phase.dirty |= changed

    def _render(
        self,
        rgb: NDArray[np.uint8],
        vignetting: NDArray[np.float32] | None,
        z: NDArray[np.int8] | NDArray[np.float32],
        z_scale: float,
        settings: tuple[float, float],
        out: NDArray[np.uint8] | None = None,
    ) -> NDArray[np.uint8]:
        """The sensor's output for ``rgb`` (a whole image or a region of it, (h, w, 3)) with the same
        region's vignetting and noise.

        Works in this thread's preallocated buffers: fresh 6 MB arrays per step cost more in page
        faults than the arithmetic.
        """
        exposure, gain = settings
        p = self.params
        dn_per_e = gain * self._qmax / p.full_well_e  # ADC codes per electron
        mean_lut = (self._linear * (p.full_well_e * exposure * dn_per_e)).astype(np.float32)
        dn, tmp, codes = _workspace(rgb.shape)
        cv2.LUT(rgb, mean_lut, dst=dn)  # mean signal in ADC codes
        if vignetting is not None:
            cv2.multiply(dn, vignetting, dst=dn)
        if p.noise:
            # variance in codes^2: shot noise (dn_per_e * S electrons) + read noise
            cv2.addWeighted(dn, dn_per_e, dn, 0.0, (p.read_noise_e * dn_per_e) ** 2, dst=tmp)
            cv2.sqrt(tmp, dst=tmp)
            cv2.multiply(tmp, z, dst=tmp, scale=z_scale, dtype=cv2.CV_32F)
            cv2.add(dn, tmp, dst=dn)
        np.add(dn, 0.5, out=dn)  # round half up by the truncation below
        np.clip(dn, 0.0, self._qmax, out=dn)
        np.copyto(codes, dn, casting="unsafe")
        if out is None:
            out = np.empty(rgb.shape, np.uint8)
        return self._out_lut.take(codes, out=out, mode="clip")  # (in range: "clip" only skips a buffer)


_WORKSPACES = threading.local()


def _workspace(shape: tuple[int, ...]) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.intp]]:
    """Two float32 buffers and one index buffer of ``shape`` (views into this thread's buffers)."""
    size = int(np.prod(shape))
    held = getattr(_WORKSPACES, "buffers", None)
    if held is None or held[0].size < size:
        held = (np.empty(size, np.float32), np.empty(size, np.float32), np.empty(size, np.intp))
        _WORKSPACES.buffers = held
    f1, f2, idx = held
    return f1[:size].reshape(shape), f2[:size].reshape(shape), idx[:size].reshape(shape)


def changed_blocks(before: NDArray[np.uint8], after: NDArray[np.uint8], chunk_px: int) -> NDArray[np.bool_]:
    """Blocks of one row by ``chunk_px`` columns where two C-contiguous (H, W, C) images differ:
    (H, ceil(W / chunk_px)), compared as 64-bit words where the rows and chunks allow."""
    h, w = before.shape[:2]
    row_bytes = before.size // h
    chunk_bytes = chunk_px * (row_bytes // w)
    word = np.uint64 if row_bytes % 8 == 0 and chunk_bytes % 8 == 0 else np.uint8
    per = chunk_bytes // np.dtype(word).itemsize
    a = before.reshape(h, row_bytes).view(word)
    b = after.reshape(h, row_bytes).view(word)
    diff = a != b
    if per % 8 == 0 and diff.shape[1] % per == 0:
        # 8 compare results at a time, as one word: numpy's any() over a short last axis is 15x slower
        packed = diff.view(np.uint64).reshape(h, -1, per // 8)
        acc = packed[:, :, 0].copy()
        for k in range(1, per // 8):
            acc |= packed[:, :, k]
        return np.asarray(acc != 0)
    return np.asarray(np.logical_or.reduceat(diff, np.arange(0, diff.shape[1], per), axis=1))


def dirty_rects(dirty: NDArray[np.bool_], chunk_px: int, width: int) -> list[tuple[int, int, int, int]]:
    """Rectangles (row0, row1, col0, col1; ends exclusive, in pixels) covering the dirty blocks of
    a (rows, chunks) mask: one per run of dirty rows, runs less than ``MERGE_ROWS`` apart joined,
    spanning the columns of the run's dirty chunks."""
    rows = np.flatnonzero(dirty.any(axis=1))
    if rows.size == 0:
        return []
    cut = np.flatnonzero(np.diff(rows) > MERGE_ROWS)
    starts = [int(rows[0]), *(int(r) for r in rows[cut + 1])]
    ends = [*(int(r) + 1 for r in rows[cut]), int(rows[-1]) + 1]
    rects = []
    for r0, r1 in zip(starts, ends, strict=True):
        cols = np.flatnonzero(dirty[r0:r1].any(axis=0))
        rects.append((r0, r1, int(cols[0]) * chunk_px, min((int(cols[-1]) + 1) * chunk_px, width)))
    return rects
