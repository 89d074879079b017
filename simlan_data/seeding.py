"""One seed drives every random choice of a run: named, independent random streams.

A run is a pure function of (config, seed). Anything random (sensor noise, fault injection,
randomized scenarios) draws from ``run_rng(cfg.seed, "what", "for whom")``: a numpy Generator
seeded from the run's seed and the stream's name through ``SeedSequence``, so streams are
independent of each other and adding a new stream does not change the numbers an existing one
draws. Never use the ``random`` module, ``np.random.<function>`` (global state), an unseeded
``default_rng()``, the wall clock or ``hash()`` of strings (salted per process) in anything that
reaches a recording or a metric; ``tests/test_determinism.py`` scans the package for them.
"""

from __future__ import annotations

import hashlib

import numpy as np


def stream_key(*names: str) -> tuple[int, ...]:
    """A stable integer key for a stream name (SHA-256, not ``hash()``, which changes per process)."""
    return tuple(int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "little") for name in names)


def run_rng(seed: int, *stream: str) -> np.random.Generator:
    """The random generator of stream ``stream`` of a run with ``seed``.

    >>> a = run_rng(7, "camera_noise", "160").normal(size=3)
    >>> bool((a == run_rng(7, "camera_noise", "160").normal(size=3)).all())
    True
    """
    if not stream:
        raise ValueError("name the stream, e.g. run_rng(seed, 'camera_noise', camera_id)")
    return np.random.Generator(
        np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=stream_key(*stream)))
    )
