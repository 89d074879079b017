"""The ``live`` section: watch a run while it goes, in Foxglove (docs/foxglove.md)."""

from __future__ import annotations

from dataclasses import dataclass

from simlan_data.errors import ConfigError


@dataclass
class LiveConfig:
    """A live view of the run: every message the recording writes, also on a Foxglove WebSocket server."""

    foxglove: bool = False  # serve the run on ws://host:port while it goes (needs the `live` extra)
    host: str = "127.0.0.1"  # 0.0.0.0: reachable from other machines
    port: int = 8765  # Foxglove's default; 0: any free port (the run prints which)
    realtime: bool = False  # never run ahead of the wall clock, so a viewer sees real speed

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise ConfigError.invalid(
                "live.port", self.port, "a TCP port is within 0..65535 (0: any free port)", "use 8765"
            )
        if not self.host.strip():
            raise ConfigError.invalid(
                "live.host", self.host, "empty", "use 127.0.0.1 (this machine) or 0.0.0.0 (every interface)"
            )

    def check_recording(self, recording_enabled: bool) -> None:
        """The live view shows what the recording writes: none without a recording."""
        if self.foxglove and not recording_enabled:
            raise ConfigError.invalid(
                "live.foxglove",
                True,
                "the live view publishes the messages the recording writes, and recording.enabled=false writes none",
                "set recording.enabled=true, or live.foxglove=false",
            )
