"""Errors users see: one line each, naming what is wrong, where, and what to do.

Format (STYLE.md): ``error: <what> in <where>: <why>; <what to do>``. Exit code 2 for bad
arguments or config, 1 for a failed run.
"""

from __future__ import annotations

EXIT_FAILED_RUN = 1
EXIT_BAD_INPUT = 2


class SimlanError(Exception):
    """Base of all errors raised on purpose by simlan_data."""

    exit_code = EXIT_FAILED_RUN

    def __init__(self, what: str, where: str = "", why: str = "", fix: str = "") -> None:
        self.what, self.where, self.why, self.fix = what, where, why, fix
        super().__init__(self.line())

    def line(self) -> str:
        """Return the single user-facing line (without the ``error:`` prefix)."""
        text = self.what
        if self.where:
            text += f" in {self.where}"
        if self.why:
            text += f": {self.why}"
        if self.fix:
            text += f"; {self.fix}"
        return text


class ConfigError(SimlanError):
    """A configuration value, override or referenced input file is invalid."""

    exit_code = EXIT_BAD_INPUT

    @classmethod
    def invalid(cls, key: str, value: object, why: str, fix: str, where: str = "config") -> ConfigError:
        """``invalid KEY=VALUE in WHERE: WHY; FIX``: a config value that fails its check."""
        return cls(f"invalid {key}={value!r}", where, why, fix)


class CalibrationError(ConfigError):
    """A camera calibration file is missing, unreadable or inconsistent."""


class AssetError(ConfigError):
    """A packaged or user-supplied asset (layout, URDF, map, motion) is invalid."""


class RecordingError(SimlanError):
    """A recording cannot be written, read or repaired."""


class RecordingInputError(RecordingError):
    """A recording given as input is not a valid simlan_data recording."""

    exit_code = EXIT_BAD_INPUT


class RunError(SimlanError):
    """A run failed after its inputs were accepted."""


class PluginError(RunError):
    """An algorithm (built-in or plug-in) raised during a run: names its role, its name and the
    simulated time. The run fails (exit 1); what was recorded up to then is finalized and kept."""
