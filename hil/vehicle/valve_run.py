"""The valve test on the tractor's own bridge: ``hil valve-test``.

At standstill, engine running, implement up, wheels free to turn: the steering-valve characterisation
(:func:`hil.vehicle.valve_steps.characterise_valve`) through the HC11 bridge on its serial port (or the
pseudo-terminal of ``hil emulate``), then the linearity of the inverse map (what the loop will see), and
the commissioning file ``commissioning.json`` that ``hil drive --commissioning`` and ``hil commission
--logs`` read. Ctrl-C or SIGTERM stops the test with the bridge disengaged; nothing half-written is left.

An AgOpenGPS steer module closes its own loop on the wheel angle, with its minimum PWM and gain set in
AgOpenGPS: it takes no duty steps, so the test is refused for it with that reason.
"""

from __future__ import annotations

import json
import signal
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import serial

from autosteer.checks import finite
from identification.outputs import atomic_write

from hil.errors import HilError
from hil.links.clock import RealClock
from hil.vehicle.bridge_spec import parse_bridge
from hil.vehicle.bridge.driver import BridgeDriver
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.commissioning import Commissioning, save_commissioning
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.valve_steps import ValveTestPlan, characterise_valve, linearity_check

__all__ = ["ValveTestConfig", "commission_valve"]


@dataclass(frozen=True)
class ValveTestConfig:
    """What the valve test needs of the tractor.

    Attributes
    ----------
    bridge_port
        The HC11 bridge's serial device (``/dev/ttyS0`` or ``hc11:/dev/ttyS0``).
    wheel_calibration
        ``(centre counts, rad per count)`` of the wheel-angle potentiometer.
    full_scale
        The bridge's steering rate at full duty, rad/s (its firmware setting).
    bridge_baud
        Line rate, bit/s.
    tractor
        Name of the tractor, for people.
    linearity
        Check the inverse map after the characterisation (about 14 more steps).
    """

    bridge_port: str
    wheel_calibration: tuple[float, float] = (128.0, 0.0061)
    full_scale: float = 0.35
    bridge_baud: int = 9600
    tractor: str = "tractor"
    linearity: bool = True

    def __post_init__(self) -> None:
        spec = parse_bridge(self.bridge_port)
        if spec.kind != "hc11":
            what = ("an ISO 11783 steering controller, which closes its own loop on the curvature (its valve is "
                    "commissioned by the tractor's maker)" if spec.kind == "isobus" else
                    "an AgOpenGPS module, which closes its own loop on the wheel angle (set its minimum PWM and gain "
                    "in AgOpenGPS)")
            raise VehicleConfigError(f"the valve test steps the valve's duty through an HC11 bridge; "
                                     f"{self.bridge_port!r} is {what}")
        WheelAngleCalibration(*self.wheel_calibration)
        finite(self.full_scale, "full_scale", lo=0.0, lo_open=True, hi=2.0, unit="rad/s",
               noun="the bridge's rate at full duty", error=VehicleConfigError)
        if not isinstance(self.tractor, str) or not self.tractor or len(self.tractor) > 200:
            raise VehicleConfigError("tractor must be a name of 1-200 characters")


def commission_valve(cfg: ValveTestConfig, out: str | Path, plan: ValveTestPlan | None = None,
                     progress: Callable[[int, int], None] | None = None,
                     open_port: Callable[..., serial.Serial] = serial.Serial) -> dict:
    """Run the valve test on the bridge of ``cfg`` and write ``out/commissioning.json`` and ``out/valve_steps.json``.

    Returns
    -------
    dict
        ``commissioning`` (the file), ``valve`` (the measured curve), ``linearity`` (or None), ``steps`` (count),
        ``seconds`` (how long the test took).

    Raises
    ------
    HilError
        The port cannot be opened (nothing was sent), or the test was stopped (Ctrl-C, SIGTERM: the bridge is
        disengaged, nothing is written).
    """
    plan = plan or ValveTestPlan()
    out = Path(out)
    cal = WheelAngleCalibration(*cfg.wheel_calibration)
    try:
        port = open_port(parse_bridge(cfg.bridge_port).device, baudrate=cfg.bridge_baud, timeout=0)
    except (serial.SerialException, OSError) as exc:
        raise HilError(f"cannot open the bridge's port: {exc}") from None
    clock = RealClock()
    driver = BridgeDriver(port, clock)
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    t0 = clock.now()
    try:
        curve, steps = characterise_valve(driver, clock, cal, cfg.full_scale, plan, progress)
        lin = linearity_check(driver, clock, cal, curve, plan=plan) if cfg.linearity else None
    except KeyboardInterrupt:
        raise HilError("valve test stopped (Ctrl-C or SIGTERM); the bridge is disengaged and nothing was written") \
            from None
    finally:
        signal.signal(signal.SIGTERM, previous)
        try:
            driver.disengage()
        except Exception:  # noqa: BLE001 - a link already gone: the bridge's watchdog cuts the valve
            pass
        port.close()
    seconds = clock.now() - t0
    com = Commissioning(cfg.tractor, curve, lin, notes=f"valve test at standstill on {cfg.bridge_port} "
                                                      f"({len(steps)} steps, {seconds:.0f} s)")
    path = save_commissioning(com, out / "commissioning.json")
    with atomic_write(out / "valve_steps.json", "w") as fh:
        fh.write(json.dumps([asdict(s) for s in steps], indent=1) + "\n")
    return {"commissioning": str(path), "valve": curve.to_dict(), "linearity": lin, "steps": len(steps),
            "seconds": seconds}


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt
