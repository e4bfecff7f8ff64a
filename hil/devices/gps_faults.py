"""The fault layer of an emulated GPS receiver: what happens to its epochs between the truth and the bytes.

As ArduPilot's simulated GPS does, a receiver here is three layers: the truth (the simulator's
recorded epochs and their errors, :mod:`hil.truth.gps_errors`), this layer, and the encoding
(:mod:`gnss.nmea_encode`) with the line timing of a UART. Every fault of a receiver is decided
here, in one place, per epoch ``k`` valid at ``t_valid`` (s, simulation time):

* outages: the epoch is not sent, when the truth's dropout draw says so (``lost[k]``) or when
  ``t_valid`` falls in an injected outage window (``outages``, ``(start, end)`` in s);
* RTK float: inside an injected window (``rtk_float``) the fix quality is reported as 5 (float)
  whatever the truth's quality;
* corruption: one bit of the encoded message flipped where the truth's draw says
  (``corruption[k]``, a fraction of the message; < 0: intact), counted in ``corrupted``.

A scenario adds windows with ``outages.extend(...)`` and ``rtk_float.extend(...)``.
"""

from __future__ import annotations

from collections.abc import Sequence

from hil.errors import SimulatorConfigError
from hil.truth.gps_errors import corrupt

__all__ = ["RTK_FLOAT_QUALITY", "ReceiverFaults"]

RTK_FLOAT_QUALITY = 5
"""GGA fix quality reported inside an RTK-float window."""


class ReceiverFaults:
    """Per-epoch faults of one receiver (see the module docstring).

    Parameters
    ----------
    lost : sequence of bool
        The truth's dropouts, one per epoch.
    corruption : sequence of float
        The truth's bit-flip draws, one per epoch: < 0 intact, else the relative position (0..1)
        of the flipped bit in the encoded message.
    """

    def __init__(self, lost: Sequence[bool], corruption: Sequence[float]) -> None:
        if len(lost) != len(corruption):
            raise SimulatorConfigError(f"ReceiverFaults: expected one dropout and one corruption draw per epoch, "
                             f"got {len(lost)} and {len(corruption)}")
        self._lost = [bool(x) for x in lost]
        self._corruption = [float(x) for x in corruption]
        self.outages: list[tuple[float, float]] = []
        self.rtk_float: list[tuple[float, float]] = []
        self.corrupted = 0

    def __len__(self) -> int:
        """Number of epochs the draws cover."""
        return len(self._lost)

    def drops(self, k: int, t_valid: float) -> bool:
        """Is epoch ``k`` (valid at ``t_valid``, s) lost: a truth dropout or inside an outage window?"""
        return self._lost[k] or bool(self.outages and any(a <= t_valid < b for a, b in self.outages))

    def quality(self, quality: int, t_valid: float) -> int:
        """The fix quality to report for an epoch whose truth quality is ``quality``."""
        if self.rtk_float and any(a <= t_valid < b for a, b in self.rtk_float):
            return RTK_FLOAT_QUALITY
        return quality

    def damage(self, k: int, data: bytes) -> bytes:
        """The encoded epoch ``k`` as it leaves the receiver (one bit flipped if the truth drew it)."""
        where = self._corruption[k]
        if where < 0:
            return data
        self.corrupted += 1
        return corrupt(data, where)
