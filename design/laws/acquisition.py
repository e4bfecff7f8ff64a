"""Line acquisition without integral windup: when a controller's integral of the cross-track runs.

A controller with integral action (the robust LMI law, the linear MPC, the NMPC) that engages
0.3-2 m off its line integrates the whole approach: the integral of ``y/V`` grows by up to
``output_clip * dt`` per step while the tractor swings in, and must then be worked off by an
error of the opposite sign. On the bench that left about -1 cm of bias for ~40 s at 1 m/s
(the four cells the robust controller missed in the main job's report). The integral's job
is the steady pull once on the line, not the approach, so it runs only while *tracking*:

* **acquiring** (after every engage, and again whenever a measured output is at its clip,
  i.e. the tractor is far from the line once more: a re-engage, a headland turn, a large
  upset): the integral is held where it is;
* **tracking** from the first cycle the cross-track has reached the line (changed sign
  relative to where the acquisition started) or come within :data:`ACQUIRE_BAND_M` of it.

On a field's headland turn (:meth:`design.laws.curvature.Reference.enter_part`) the implement is raised,
so the pull the integrals learnt on the pass is not there: :class:`HeadlandIntegrals` sets them aside
(zero over the turn, held there) and gives them back where the next pass starts.

Once tracking, the controller is exactly its certified linear law (the integral included),
so a certificate computed on the linear closed loop describes the loop that runs after
acquisition; during the acquisition the loop is that law with the integral frozen (at its
engage value, zero), which the tests check is stable on the design's models.
"""

from __future__ import annotations

import math

import numpy as np

from autosteer.checks import positive

from design.core.errors import DesignInputError

#: Cross-track within which the line counts as acquired even without a crossing, m.
ACQUIRE_BAND_M = 0.01
#: Longest time between the last step before a disengage and the first after the re-engage over which
#: a controller's integrals keep their value (the steady pull they had learnt: an implement's side
#: force does not change over a short disengage), s; after a longer gap they start at 0.
INTEGRAL_MEMORY_S = 10.0


def integral_kept(gap: float) -> bool:
    """True if integrals learnt ``gap`` s before a re-engage are kept (``0 <= gap <= INTEGRAL_MEMORY_S``)."""
    return 0.0 <= gap <= INTEGRAL_MEMORY_S


class IntegralGate:
    """Says, each cycle, whether a controller's integral may run (see the module docstring).

    Parameters
    ----------
    band
        Cross-track within which the line counts as acquired, m (> 0).
    crossing
        Hold the integral after an engage until the line is reached (else only while an output
        is at its clip: for a law whose own prediction already handles the approach, the MPC).
    """

    def __init__(self, band: float = ACQUIRE_BAND_M, crossing: bool = True) -> None:
        self.band = positive(band, "acquisition band", unit="m", noun="a finite distance", error=DesignInputError)
        self.crossing = bool(crossing)
        self.reset()

    def reset(self) -> None:
        """Start a new acquisition (called on every engage)."""
        self.tracking = not self.crossing
        self._start = math.nan          # cross-track where the acquisition started, m

    def integrate(self, cross_track: float, clipped: bool) -> bool:
        """Update the state with this cycle's measurement; True if the integral may run this cycle.

        Parameters
        ----------
        cross_track
            Measured cross-track, m, + left.
        clipped
            Some measured output was at its clip this cycle (far from the line).
        """
        if not math.isfinite(cross_track):
            return False
        if clipped:
            self.tracking = not self.crossing
            self._start = cross_track
            return False
        if not self.tracking:
            if math.isnan(self._start):
                self._start = cross_track
            if abs(cross_track) <= self.band or cross_track * self._start <= 0.0:
                self.tracking = True
        return self.tracking


class HeadlandIntegrals:
    """A controller's integrals set aside over a headland turn, given back where the next pass starts.

    The implement is raised on the headland: applied there, the pull the integrals learnt on the pass
    would steer the turn off its path by as much and bring the tractor onto the next pass off its
    line (measured: 3-7 cm with the disker at 2.91 m/s on a calm simulator), and learnt there, the
    turn's own slip would be carried into the next pass. So over the turn the integrals are zero and
    held (the reference does not count the line as acquired there), and where the next pass starts
    they take back the values they had where the turn began.
    """

    def __init__(self) -> None:
        self.parked: np.ndarray | None = None

    def enter(self, was: bool, now: bool, kept: np.ndarray) -> np.ndarray | None:
        """The headland flag went from ``was`` to ``now``; ``kept`` are the integrals of the last step.

        Returns the values the integrals take from now on (zeros entering a turn, the set-aside values
        leaving it), or None for no change. Entering again (a re-engage on the turn) keeps the values
        set aside first.
        """
        if now and not was:
            if self.parked is None:
                self.parked = np.array(kept, dtype=float)
            return np.zeros(len(kept))
        if was and not now and self.parked is not None:
            out, self.parked = self.parked, None
            return out
        return None

    def forget(self) -> None:
        """Drop the set-aside values (a re-engage after longer than :data:`INTEGRAL_MEMORY_S`: no integral is kept)."""
        self.parked = None
