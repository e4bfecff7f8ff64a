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

A pole *pair* above a quarter of the sample rate is named too when it is a lightly damped
resonance, however fast it decays: its gain peak is at least :data:`RESONANCE_PEAK` (twice) its
static gain, a damping ratio below :data:`RESONANCE_DAMPING` (0.26). Between a quarter of the
rate and the Nyquist frequency an oscillation lasts 2 to 4 samples per period; the tractor has
none there (the valve and the wheel are first-order lags under 2 Hz, the yaw modes slower): a
sampled lag is a pole on the positive real axis, and a low-order fit of a fraction of a sample
of latency puts a pole or zero on the negative one, never a pair. A fitted pair there is the
noise of the fit; its gain peak at 5-10 Hz is a loop gain the controller must survive on that
one model. On the held-out random-102 tractor ``local_ripper_5th`` at order 8 (score 80.8
against 75.8 at order 4) had a pair at ``-0.472+-0.479j``: 7.5 Hz, damping ratio 0.17, gone in
0.13 s (so under :data:`ARTEFACT_DECAY_S`); the one robust law every speed band falls back to
could not be made faster than scale 0.05 without losing the disk margin on that model, and
reached 2.6 with the order-4 model in its place (the law of the speed band under 1.4 m/s: 0.16
before, 3.8). A pair damped more has no peak to speak of (random-107's ``local_disker_13th``,
0.39: 1.4 times) and is left to the decay bound, as are real poles on the negative axis: most
models of order 5 carry one (``-0.01`` to ``-0.77`` over 21 commissioned tractors). Over those
tractors 16 of 273 models (on 12 tractors) had a lightly damped pair that the decay bound let in.
"""

from __future__ import annotations

import math

import numpy as np

#: Lowest frequency of a mode counted as an artefact, Hz (a quarter of the 20 Hz sample rate).
ARTEFACT_HZ = 5.0
#: A mode above :data:`ARTEFACT_HZ` that decays more slowly than this, s, is an artefact
#: (with 5 Hz: a damping ratio below about 0.16).
ARTEFACT_DECAY_S = 0.2
#: A complex pole pair above :data:`ARTEFACT_HZ` whose second-order gain peak ``1 / (2 z sqrt(1 - z^2))``
#: (damping ratio ``z``) is at least this many times its static gain is an artefact however fast it decays.
RESONANCE_PEAK = 2.0
#: The damping ratio of that peak, about 0.26: a pair damped less is named.
RESONANCE_DAMPING = math.sqrt((1.0 - math.sqrt(1.0 - 1.0 / RESONANCE_PEAK ** 2)) / 2.0)


def damping_ratio(p: complex, dt: float) -> float:
    """Damping ratio of the continuous-time mode ``ln(p) / dt`` of the discrete pole ``p`` (1 for ``p = 0``)."""
    r = abs(p)
    if r <= 0.0:
        return 1.0
    sigma, theta = math.log(r), abs(float(np.angle(p)))
    return -sigma / math.hypot(sigma, theta) if (sigma or theta) else 0.0


def sampling_artefact(a: np.ndarray, dt: float) -> str | None:
    """Describe the first fast mode of the state matrix ``a`` that a sampled tractor does not have, or ``None``.

    Parameters
    ----------
    a
        Discrete-time state matrix (sample time ``dt``).
    dt
        Sample time, s.

    Returns
    -------
    str or None
        For a pole ``p`` whose frequency ``|arg p| / (2 pi dt)`` is at least :data:`ARTEFACT_HZ`:
        ``"pole -0.983 (10.0 Hz, decays in 1.2 s)"`` if its decay time ``-dt / ln|p|`` exceeds
        :data:`ARTEFACT_DECAY_S`, else ``"pole -0.472+0.479j (7.5 Hz, damping ratio 0.17, a
        resonance)"`` if it is one of a complex pair whose damping ratio
        (:func:`damping_ratio`) is below :data:`RESONANCE_DAMPING`; ``None`` if there is none.
    """
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"sample time must be a finite number > 0 s, got {dt!r}")
    poles = np.linalg.eigvals(np.asarray(a, dtype=float))
    for p in sorted(poles, key=lambda z: (-abs(z), -z.imag)):
        r = abs(p)
        hz = abs(float(np.angle(p))) / (2.0 * math.pi * dt)
        if hz < ARTEFACT_HZ - 1e-9 or r <= 0.0:
            continue
        decay = math.inf if r >= 1.0 else -dt / math.log(r)
        pair = abs(p.imag) > 1e-9
        z = f"{p.real:.3f}{p.imag:+.3f}j" if pair else f"{p.real:.3f}"
        if decay > ARTEFACT_DECAY_S:
            return f"pole {z} ({hz:.1f} Hz, decays in {decay:.2g} s)"
        zeta = damping_ratio(p, dt)
        if pair and zeta < RESONANCE_DAMPING:
            return f"pole {z} ({hz:.1f} Hz, damping ratio {zeta:.2f}, a resonance)"
    return None
