"""Emulated GPS receivers: the simulator's GPS epochs encoded as NMEA byte streams.

Three layers, as in ArduPilot's simulated GPS: the truth and its errors come from
the simulator (:mod:`hil.truth.gps_errors`, drawn per pass: white noise, multipath, latency,
outages, RTK float episodes, and messages with a flipped bit), every fault of a receiver is
applied by its fault layer (:class:`hil.devices.gps_faults.ReceiverFaults`: outages, RTK float
windows, bit flips), the encoding comes from :mod:`gnss` (the same encoders the front-end's tests
round-trip), and line timing from a UART at the receiver's baud rate. Each receiver is a device on the bench clock
(``next_wakeup`` / ``step``) writing to a byte link, so the same receiver feeds an
in-memory link in lockstep or a pseudo-terminal in real time.

* :class:`PositionReceiver` - ``GGA`` + ``VTG`` at 5 Hz (fix quality 4 or 5).
* :class:`AttitudeReceiver` - Trimble ``$PTNL,AVR`` at 10 Hz (yaw, tilt, roll).

The simulator's frame (x along the AB line or the first pass of a field's route, y left) is
placed on the Earth by :class:`gnss.field.FieldGeometry`: a field origin (WGS-84) and the heading
of the frame's x axis. A field's route is defined in that frame; :meth:`~gnss.field.FieldGeometry.place`
gives the same route in the vehicle's ENU frame.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gnss.geodesy_scalar import ScalarFrame
from gnss.messages import Avr, Gga, Vtg
from gnss.nmea_encode import encode_avr, encode_gga, encode_vtg

from hil.links.link import ByteLink
from hil.links.uart import LineConfig, UartTx
from hil.devices.gps_faults import ReceiverFaults
from hil.devices.plant import SimulatedTractor

if TYPE_CHECKING:      # annotations only: the geometry lives with the fields, it is not re-exported here
    from gnss.field import FieldGeometry

_EPS = 1e-9


class _Receiver:
    """Common device logic: epochs become due at their arrival time; lost ones are skipped."""

    def __init__(self, tractor: SimulatedTractor, link: ByteLink, geometry: FieldGeometry,
                 line: LineConfig, rate: float, latency: float, jitter: np.ndarray, lost: np.ndarray,
                 corruption: np.ndarray) -> None:
        self.tractor = tractor
        self.geometry = geometry
        self.uart = UartTx(line, link)
        self.rate, self.latency = rate, latency
        # per-epoch values as Python lists (read once per epoch, and next_wakeup is asked often)
        self._jitter = jitter.tolist()
        self.faults = ReceiverFaults(lost.tolist(), corruption.tolist())   # outages, RTK float, bit flips
        self._n = len(self.faults)
        self._due = self._arrival(0) if self._n else math.inf
        self.k = 0
        self._retry = -math.inf
        self._wake = self._due      # the later of _due and _retry, kept with them (next_wakeup is asked often)
        self.sent = 0

    @property
    def suppressed(self) -> list[tuple[float, float]]:
        """Injected outage windows, (start, end) s with no output (``faults.outages``)."""
        return self.faults.outages

    @property
    def corrupted(self) -> int:
        """Epochs sent with a flipped bit (``faults.corrupted``)."""
        return self.faults.corrupted

    def _arrival(self, k: int) -> float:
        return k / self.rate + self.latency + self._jitter[k]

    def next_wakeup(self) -> float:
        uart = self.uart
        if not uart.holds:
            return self._wake
        due, held = self._wake, uart.next_due()
        return due if due < held else held

    def step(self, now: float) -> None:
        uart = self.uart
        if uart.holds:
            uart.flush(now)
        while self._due <= now + _EPS:
            if self._recorded() <= self.k:        # the plant has not reached the epoch yet
                self._retry = retry = now + self.tractor.params.dt
                self._wake = self._due if self._due > retry else retry
                return
            k = self.k
            self.k += 1
            self._due = self._arrival(self.k) if self.k < self._n else math.inf
            t_valid = k / self.rate
            faults = self.faults
            if faults.drops(k, t_valid):
                continue
            uart.send(faults.damage(k, self._encode(k, t_valid)), now)
            self.sent += 1
        self._retry = -math.inf
        self._wake = self._due
        if uart.holds:
            uart.flush(now)

    def _recorded(self) -> int:
        raise NotImplementedError

    def _encode(self, k: int, t_valid: float) -> bytes:
        raise NotImplementedError


class PositionReceiver(_Receiver):
    """RTK position receiver: ``$GPGGA`` then ``$GPVTG`` every 0.2 s.

    Parameters
    ----------
    tractor
        The simulated tractor whose GPS epochs are sent.
    link
        Byte link to the vehicle computer (in-memory or pseudo-terminal).
    geometry
        Field placement of the guidance line.
    line
        Serial line format (default 38400 8N1).
    """

    def __init__(self, tractor: SimulatedTractor, link: ByteLink, geometry: FieldGeometry,
                 line: LineConfig | None = None) -> None:
        g, err = tractor.params.gps, tractor.sim.gps_errors
        super().__init__(tractor, link, geometry, line or LineConfig(baud=38400), g.position_rate,
                         g.position_latency, err.pos_jitter[0], err.pos_lost[0], err.pos_corrupt[0])
        self._frame = ScalarFrame(geometry.origin)
        self._line_sin_cos = (math.sin(geometry.line_yaw), math.cos(geometry.line_yaw))

    @property
    def downgraded(self) -> list[tuple[float, float]]:
        """Injected RTK-float windows, (start, end) s reported as fix quality 5 (``faults.rtk_float``)."""
        return self.faults.rtk_float

    def _recorded(self) -> int:
        # an epoch the simulator has recorded is final: catch the integration up only to look for a newer one
        n = self.tractor.sim.n_pos
        return n if n > self.k else self.tractor.sim.n_pos

    def _encode(self, k: int, t_valid: float) -> bytes:
        sim, geo = self.tractor.sim, self.geometry     # epoch k is recorded (step checked it)
        pos = sim.pos
        x, y = pos["x"].item(0, k), pos["y"].item(0, k)     # float(a[0, k]) without the numpy scalar
        s, c = self._line_sin_cos                  # geo.line_to_enu(x, y), with sin and cos taken once
        east, north = x * s - y * c, x * c + y * s
        up = self.tractor.params.vehicle.antenna_height
        lat, lon, h = self._frame.to_geodetic(east, north, up)
        quality = self.faults.quality(int(pos["fix"].item(0, k)), t_valid)
        tod = (geo.utc_start + t_valid) % 86400.0
        ia = int(round(t_valid * sim.params.gps.attitude_rate))
        n_att = sim.n_att if ia < sim.n_att else self.tractor.sim.n_att   # catch up only if it is not recorded
        ia = min(ia, n_att - 1)
        course = geo.yaw(sim.att["yaw"].item(0, ia))
        diff_age = 1.0 if quality in (4, 5) else None
        return (encode_gga(Gga("GP", tod, lat, lon, quality, 14, 0.8, h, 0.0, diff_age, 1))
                + encode_vtg(Vtg("GP", course, None, pos["speed"].item(0, k), "D")))


class AttitudeReceiver(_Receiver):
    """Multi-antenna attitude receiver: Trimble ``$PTNL,AVR`` every 0.1 s."""

    def __init__(self, tractor: SimulatedTractor, link: ByteLink, geometry: FieldGeometry,
                 line: LineConfig | None = None) -> None:
        g, err = tractor.params.gps, tractor.sim.gps_errors
        super().__init__(tractor, link, geometry, line or LineConfig(baud=38400), g.attitude_rate,
                         g.attitude_latency, err.att_jitter[0], err.att_lost[0], err.att_corrupt[0])

    def _recorded(self) -> int:
        n = self.tractor.sim.n_att     # as PositionReceiver._recorded
        return n if n > self.k else self.tractor.sim.n_att

    def _encode(self, k: int, t_valid: float) -> bytes:
        att, geo = self.tractor.sim.att, self.geometry   # epoch k is recorded (step checked it)
        tod = (geo.utc_start + t_valid) % 86400.0
        return encode_avr(Avr(tod, geo.yaw(att["yaw"].item(0, k)), att["pitch"].item(0, k), att["roll"].item(0, k),
                              1.5, 3, 1.6, 12))
