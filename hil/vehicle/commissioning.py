"""A tractor's commissioning file, the loop's plausibility thresholds it implies, and the mapped bridge.

The commissioning file (JSON) holds what the valve characterisation measured
(:class:`~hil.vehicle.valve_map.ValveCurve`), the linearity of the inverse map when it was
checked, and free-text notes::

    {"format": "tractor-autosteer commissioning", "version": 1, "tractor": "heavy-11t",
     "valve": {"full_scale": 0.35, "deadband": 0.12, ...}, "linearity": {...} | null, "notes": "..."}

Reading is bounded (:data:`MAX_FILE_BYTES`, a JSON nesting depth) and validates every field and
refuses unknown keys. :func:`loop_settings` turns the measured
actuator into the vehicle loop's settings (rate limit and steering-response monitor) instead of
the constants of :class:`~hil.vehicle.loop.LoopConfig`; :class:`MappedBridge` applies the
inverse map where the loop's rate command becomes what the bridge turns into a duty.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from autosteer.checks import positive
from autosteer.bounded import read_json
from identification.outputs import atomic_write

from hil.vehicle.bridge.driver import BridgeDriver
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.loop import LoopConfig
from hil.vehicle.valve_map import ValveCurve

__all__ = ["Commissioning", "load_commissioning", "save_commissioning", "loop_settings", "MappedBridge",
           "MONITOR_MARGIN", "NOISE_SIGMAS"]

FORMAT = "tractor-autosteer commissioning"
VERSION = 1
_KEYS = {"format", "version", "tractor", "valve", "linearity", "notes"}
#: Largest commissioning file read, bytes (one is about 2 kB; free-text notes included, 1 MiB is ample).
MAX_FILE_BYTES = 2**20
_LINEARITY_KEYS = {"wanted", "measured", "max_error", "max_error_fraction"}

#: The response monitor trips when the wheel moved less than this fraction of the commanded motion
#: (less the map's linearity error): a stuck valve, ratio ~0, is far below; a healthy linearised one,
#: ratio ~1 once the commanded motion exceeds what its delay can hide, far above.
MONITOR_MARGIN = 0.3
#: The monitor judges only commands whose expected wheel motion is this many sigma of the
#: difference of two reports (so report noise alone never trips it).
NOISE_SIGMAS = 6.0


@dataclass(frozen=True)
class Commissioning:
    """What commissioning measured on one tractor.

    Parameters
    ----------
    tractor
        Name of the tractor (free text, for people).
    valve
        The measured valve curve (its inverse map is applied by :class:`MappedBridge`).
    linearity
        Result of :func:`~hil.vehicle.valve_steps.linearity_check` (``None`` if not run).
    notes
        Free text.
    """

    tractor: str
    valve: ValveCurve
    linearity: Mapping[str, Any] | None = None
    notes: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.tractor, str) or not isinstance(self.notes, str):
            raise VehicleConfigError("commissioning: 'tractor' and 'notes' must be strings")
        if not isinstance(self.valve, ValveCurve):
            raise VehicleConfigError(f"commissioning: 'valve' must be a ValveCurve, got {type(self.valve).__name__}")
        if self.linearity is not None:
            object.__setattr__(self, "linearity", _check_linearity(self.linearity))

    def loop_config(self, base: LoopConfig | None = None) -> LoopConfig:
        """The loop settings for this tractor (:func:`loop_settings` with the measured linearity)."""
        err = None if self.linearity is None else self.linearity["max_error_fraction"]
        return loop_settings(self.valve, base, err)

    def to_dict(self) -> dict[str, Any]:
        """The file's content (JSON-serialisable)."""
        return {"format": FORMAT, "version": VERSION, "tractor": self.tractor, "valve": self.valve.to_dict(),
                "linearity": None if self.linearity is None else dict(self.linearity), "notes": self.notes}

    @classmethod
    def from_dict(cls, d: Any, where: str = "commissioning") -> "Commissioning":
        """Inverse of :meth:`to_dict`; every field validated, unknown keys refused."""
        if not isinstance(d, Mapping):
            raise VehicleConfigError(f"{where}: expected a JSON object, got {type(d).__name__}")
        unknown = set(d) - _KEYS
        if unknown:
            raise VehicleConfigError(f"{where}: unknown key(s) {sorted(unknown)}; a commissioning file has "
                                     f"{sorted(_KEYS)}")
        if d.get("format") != FORMAT or d.get("version") != VERSION:
            raise VehicleConfigError(f"{where}: not a commissioning file (expected format {FORMAT!r} version "
                                     f"{VERSION}, got {d.get('format')!r} version {d.get('version')!r})")
        valve = d.get("valve")
        if not isinstance(valve, Mapping):
            raise VehicleConfigError(f"{where}: 'valve' must be an object with the valve curve's fields")
        known = {f.name for f in dataclasses.fields(ValveCurve)}
        if set(valve) != known:
            raise VehicleConfigError(f"{where}: 'valve' must have exactly the fields {sorted(known)}; "
                                     f"missing {sorted(known - set(valve))}, unknown {sorted(set(valve) - known)}")
        try:
            curve = ValveCurve(**valve)
        except VehicleConfigError as exc:
            raise VehicleConfigError(f"{where}: {exc}") from None
        return cls(tractor=d.get("tractor", ""), valve=curve, linearity=d.get("linearity"), notes=d.get("notes", ""))


def _check_linearity(lin: Any) -> dict[str, Any]:
    if not isinstance(lin, Mapping) or set(lin) != _LINEARITY_KEYS:
        raise VehicleConfigError(f"commissioning: 'linearity' must be null or an object with {sorted(_LINEARITY_KEYS)}")
    out: dict[str, Any] = {}
    for k in ("wanted", "measured"):
        v = lin[k]
        if not isinstance(v, (list, tuple)) or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                      and math.isfinite(x) for x in v):
            raise VehicleConfigError(f"commissioning: linearity.{k} must be a list of finite rates, rad/s")
        out[k] = [float(x) for x in v]
    if len(out["wanted"]) != len(out["measured"]):
        raise VehicleConfigError("commissioning: linearity.wanted and .measured must have the same length")
    for k in ("max_error", "max_error_fraction"):
        out[k] = positive(lin[k], f"commissioning: linearity.{k}", allow_zero=True, error=VehicleConfigError)
    return out


def save_commissioning(c: Commissioning, path: str | Path) -> Path:
    """Write the commissioning file (JSON); returns the path."""
    path = Path(path)
    with atomic_write(path, "w") as fh:
        fh.write(json.dumps(c.to_dict(), indent=2) + "\n")
    return path


def load_commissioning(path: str | Path) -> Commissioning:
    """Read and validate a commissioning file."""
    path = Path(path)
    if not path.exists():
        raise VehicleConfigError(f"commissioning file {str(path)!r} does not exist; make one with "
                                 "`hil valve-test` on the tractor (or `hil commission` on the bench)")
    d = read_json(path, MAX_FILE_BYTES, "commissioning file", VehicleConfigError)
    return Commissioning.from_dict(d, where=f"commissioning file {str(path)!r}")


def loop_settings(valve: ValveCurve, base: LoopConfig | None = None, linearity_error: float | None = None) -> LoopConfig:
    """The loop's rate limit and steering-response monitor from the measured actuator.

    The monitor (:class:`~hil.vehicle.loop.LoopConfig`) compares the wheel's motion over a window
    with the sum of the rates commanded in it. A healthy valve of delay ``lag`` moves the wheel by
    the commands of the window shifted by ``lag``, so the two differ by at most ``2 lag max_rate``
    (the commands that left at one end and not yet arrived at the other), plus the map's error and
    the report noise. Hence:

    * ``max_rate``: the rate the valve reaches both ways, ``valve.max_rate`` (the inverse map can
      make no more of the weaker side).
    * ``response_window``: at least six delays (a lagging valve needs longer to show that it follows)
      and long enough that the rate limit held over half of it reaches ``response_min_command``
      (else a stuck valve could never be judged).
    * ``response_min_ratio``: :data:`MONITOR_MARGIN` less the map's measured linearity error
      (``linearity_error``, a fraction of ``max_rate``; 0.15 if unknown).
    * ``response_min_command``: the commanded motion from which a healthy valve always moves more
      than ``response_min_ratio`` of it: ``(2 lag max_rate (1 + error) + k sqrt(2) noise) / (1 - ratio)``,
      ``k`` = :data:`NOISE_SIGMAS`, noise = the reports' 1-sigma.
    * ``wheel_step``: the plausibility check's motion allowed between two reports beyond the valve's rate,
      at least ``k sqrt(2) noise`` (a noisy potentiometer's reports are not a wheel faster than the valve).

    Parameters
    ----------
    valve
        The measured valve curve.
    base
        The other settings (default :class:`LoopConfig`).
    linearity_error
        Largest deviation of the linearised rate from the wanted one, fraction of ``max_rate``.

    Returns
    -------
    LoopConfig
        ``base`` with those five settings replaced.
    """
    base = base or LoopConfig()
    err = 0.15 if linearity_error is None else min(max(float(linearity_error), 0.0), 0.5)
    min_ratio = MONITOR_MARGIN * (1.0 - err)
    spread = 2.0 * valve.lag * valve.max_rate * (1.0 + err) + NOISE_SIGMAS * math.sqrt(2.0) * valve.angle_noise
    min_command = spread / (1.0 - min_ratio)
    window = max(base.response_window, 6.0 * valve.lag, 2.0 * min_command / valve.max_rate)
    # the plausibility check's step between two reports covers the sensor's measured noise: the difference of
    # two noisy reports must never read as a wheel faster than the valve
    step = max(base.wheel_step, NOISE_SIGMAS * math.sqrt(2.0) * valve.angle_noise)
    return dataclasses.replace(base, max_rate=valve.max_rate, response_window=window,
                               response_min_ratio=min_ratio, response_min_command=min_command, wheel_step=step)


class MappedBridge:
    """A bridge driver whose rate commands go through the valve's inverse map.

    The loop (or anyone) asks for a wheel-angle rate; :meth:`send_rate` sends the command the
    measured valve needs for it (:meth:`ValveCurve.command_for`). Everything else is the
    driver's own (reports, engage, statistics).

    Parameters
    ----------
    driver
        The bridge driver.
    valve
        The measured valve curve.
    """

    def __init__(self, driver: BridgeDriver, valve: ValveCurve) -> None:
        self.driver = driver
        self.valve = valve
        self._command_for = valve.command_for

    def send_rate(self, rate: float) -> int:
        """Send the command that makes the valve run at ``rate`` rad/s (+ left); returns the sequence number."""
        return self.driver.send_rate(self._command_for(rate))

    def __getattr__(self, name: str) -> Any:
        return getattr(self.driver, name)
