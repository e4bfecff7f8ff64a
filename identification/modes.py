"""Modes a sampled tractor does not have: lightly damped oscillations near the Nyquist frequency.

A tractor's lateral motion, its steering valve's lag and its GPS filters live below 2-3 Hz;
sampled at 20 Hz their poles lie on the positive real axis or at small angles. OKID at a free
order can spend a state on a pole near ``z = -1`` (or elsewhere at 5-10 Hz, close to the unit
circle) that buys a point of held-out fit from the noise of the wheel-angle sensor: on the
worn-valve tractor's ``local_none_13th`` (order 5, held-out score 87.4 against 86.8 at order 4)
a pole at ``-0.983``, a 10 Hz oscillation with a damping ratio of 0.005. Such a mode has a
loop gain at the Nyquist frequency about 50 times the other models' (the steering channel's
``|P(-1)|`` 0.078 against 0.0004-0.012 rad per rad/s), so one extra sample of delay flips
its sign and the design's delay reserve fails there: the weight search of the worn valve's MPC
stopped at scale 1.70 on that one model. The same MPC at scale 3.5 (every other specification
met on every other model) held the 15 HIL cells of that tractor within both commissioning bounds (worst
1.27x the oracle, against 1.31-1.43x at 1.70): the mode was not the tractor's.

:func:`sampling_artefact` names such a mode; :func:`identification.selection.fit_select` does
not choose a candidate that has one when another candidate is free of it (the tractor
identification asks it to, :mod:`identification.tractor`; a generic identification does not,
since a plant may have real fast resonances). Over a campaign of 22 tractors 49 of 418
models had one.
"""

from __future__ import annotations

import math

import numpy as np

#: Lowest frequency of a mode counted as an artefact, Hz (a quarter of the 20 Hz sample rate).
ARTEFACT_HZ = 5.0
#: A mode above :data:`ARTEFACT_HZ` that decays more slowly than this, s, is an artefact
#: (with 5 Hz: a damping ratio below about 0.16).
ARTEFACT_DECAY_S = 0.2


def sampling_artefact(a: np.ndarray, dt: float) -> str | None:
    """Describe the first lightly damped fast mode of the state matrix ``a``, or ``None``.

    Parameters
    ----------
    a
        Discrete-time state matrix (sample time ``dt``).
    dt
        Sample time, s.

    Returns
    -------
    str or None
        ``"pole -0.983 (10.0 Hz, decays in 1.2 s)"`` for a pole ``p`` whose frequency
        ``|arg p| / (2 pi dt)`` is at least :data:`ARTEFACT_HZ` and whose decay time
        ``-dt / ln|p|`` exceeds :data:`ARTEFACT_DECAY_S`; ``None`` if there is none.
    """
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"sample time must be a finite number > 0 s, got {dt!r}")
    poles = np.linalg.eigvals(np.asarray(a, dtype=float))
    for p in sorted(poles, key=lambda z: -abs(z)):
        r = abs(p)
        hz = abs(float(np.angle(p))) / (2.0 * math.pi * dt)
        if hz < ARTEFACT_HZ - 1e-9 or r <= 0.0:
            continue
        decay = math.inf if r >= 1.0 else -dt / math.log(r)
        if decay > ARTEFACT_DECAY_S:
            z = f"{p.real:.3f}" if abs(p.imag) < 1e-9 else f"{p.real:.3f}{p.imag:+.3f}j"
            return f"pole {z} ({hz:.1f} Hz, decays in {decay:.2g} s)"
    return None
