"""Validated configuration of the emulated bridge firmware and of the host driver."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from autosteer.checks import finite, positive

from hil.vehicle.bridge.errors import ConfigError
from hil.vehicle.bridge.protocol import MAX_PAYLOAD, MESSAGE_TABLE, RATE_SCALE
from hil.links.errors import LinkConfigError
from hil.links.uart import LineConfig

__all__ = ["FirmwareConfig", "DriverConfig"]


_LARGEST = max(layout.size for layout in MESSAGE_TABLE.values())


def _payload_limit(value: object) -> None:
    finite(value, "max_payload", lo=_LARGEST, hi=255, integer=True, unit="bytes", error=ConfigError,
           fix=f"the largest message needs {_LARGEST}")


def _build(cls: type, options: Mapping[str, Any], nested: Mapping[str, Any] | None = None) -> Any:
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ConfigError(f"unknown {cls.__name__} option(s) {unknown}; known options: {sorted(known)}")
    values = dict(options)
    for key, sub in (nested or {}).items():
        if key in values and isinstance(values[key], Mapping):
            try:
                values[key] = sub.from_mapping(values[key])
            except LinkConfigError as err:
                raise ConfigError(f"{cls.__name__}.{key}: {err}") from err
    return cls(**values)


@dataclass(frozen=True)
class FirmwareConfig:
    """Settings of the emulated MC68HC11 steering bridge.

    Parameters
    ----------
    line : LineConfig
        Serial line format (default 9600 8N1: 960 bytes/s).
    report_period : float
        Wheel-angle report period, s (default 0.05: 20 Hz).
    watchdog_timeout : float
        The valve is cut and the watchdog flag set when no valid steering-rate
        command arrived for this long while engaged, s (default 0.25).
    max_rate : float
        Nominal steering rate at full valve duty, rad/s (default 0.35). A command
        ``u`` gives duty ``clip(u / max_rate, -1, 1)``; the valve's real
        deadband, asymmetry and lag belong to the plant.
    input_poll_period : float
        The manual-override input is sampled at least this often, s (default 0.01).
    max_payload : int
        Largest payload length the frame decoder waits for, bytes (default 32).
    """

    line: LineConfig = field(default_factory=LineConfig)
    report_period: float = 0.05
    watchdog_timeout: float = 0.25
    max_rate: float = 0.35
    input_poll_period: float = 0.01
    max_payload: int = MAX_PAYLOAD

    def __post_init__(self) -> None:
        if not isinstance(self.line, LineConfig):
            raise ConfigError(f"line must be a LineConfig, got {type(self.line).__name__}")
        positive(self.report_period, "report_period", unit="s", error=ConfigError)
        positive(self.watchdog_timeout, "watchdog_timeout", unit="s", error=ConfigError)
        positive(self.max_rate, "max_rate", unit="rad/s", error=ConfigError)
        positive(self.input_poll_period, "input_poll_period", unit="s", error=ConfigError)
        if self.watchdog_timeout < self.report_period:
            raise ConfigError(f"watchdog_timeout ({self.watchdog_timeout} s) shorter than report_period "
                              f"({self.report_period} s) would trip between two host cycles; lengthen it")
        _payload_limit(self.max_payload)
        if self.max_rate / RATE_SCALE < 100:
            raise ConfigError(f"max_rate {self.max_rate} rad/s is under 100 command steps of {RATE_SCALE} rad/s")

    @classmethod
    def from_mapping(cls, options: Mapping[str, Any]) -> FirmwareConfig:
        """Build from a mapping (``line`` may be a mapping too), refusing unknown options."""
        return _build(cls, options, {"line": LineConfig})


@dataclass(frozen=True)
class DriverConfig:
    """Settings of the host-side bridge driver.

    Parameters
    ----------
    poll_interval : float
        Sleep between link polls while a blocking call waits, s (default 0.0005).
        On a real clock with a link that has ``fileno()``, ``select`` is used instead.
    report_timeout : float
        The bridge counts as silent when no report arrived for this long, s
        (default 0.15: three report periods).
    max_pending_reports : int
        Reports kept for :meth:`~hil.vehicle.bridge.driver.BridgeDriver.poll`; older ones
        are dropped and counted (default 64).
    read_chunk : int
        Most bytes read from the link in one go (default 4096).
    max_payload : int
        Largest payload length the frame decoder waits for, bytes (default 32).
    """

    poll_interval: float = 0.0005
    report_timeout: float = 0.15
    max_pending_reports: int = 64
    read_chunk: int = 4096
    max_payload: int = MAX_PAYLOAD

    def __post_init__(self) -> None:
        positive(self.poll_interval, "poll_interval", unit="s", error=ConfigError)
        positive(self.report_timeout, "report_timeout", unit="s", error=ConfigError)
        for name in ("max_pending_reports", "read_chunk"):
            finite(getattr(self, name), name, lo=1, integer=True, error=ConfigError)
        _payload_limit(self.max_payload)

    @classmethod
    def from_mapping(cls, options: Mapping[str, Any]) -> DriverConfig:
        """Build from a mapping, refusing unknown options."""
        return _build(cls, options)
