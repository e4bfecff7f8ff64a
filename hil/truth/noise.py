"""Random processes used by the simulator: coloured noise and on/off episodes.

Every function takes an explicit ``numpy.random.Generator``; nothing here touches
global random state.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter


def ou_noise(rng: np.random.Generator, n: int, dt: float, sigma: float, tau: float) -> np.ndarray:
    """Stationary first-order Gauss-Markov (Ornstein-Uhlenbeck) sequence.

    Parameters
    ----------
    rng
        Random generator.
    n
        Number of samples.
    dt
        Sample time, s.
    sigma
        Stationary standard deviation (unit of the result).
    tau
        Correlation time, s (> 0).

    Returns
    -------
    numpy.ndarray
        ``n`` samples, starting from the stationary distribution.
    """
    a = float(np.exp(-dt / tau))
    w = rng.standard_normal(n)
    w[0] *= 1.0 / np.sqrt(1.0 - a * a)  # start in the stationary distribution
    return sigma * np.sqrt(1.0 - a * a) * lfilter([1.0], [1.0, -a], w)


def episodes(rng: np.random.Generator, n: int, start_prob: float, mean_len: float) -> np.ndarray:
    """Boolean mask of random episodes (a two-state Markov chain).

    Parameters
    ----------
    n
        Number of epochs.
    start_prob
        Probability that an episode starts at an epoch (overlapping episodes merge).
    mean_len
        Mean episode length in epochs (>= 1).
    """
    mask = np.zeros(n, dtype=bool)
    if start_prob <= 0 or n == 0:
        return mask
    starts = np.flatnonzero(rng.random(n) < start_prob)
    lengths = rng.geometric(1.0 / max(mean_len, 1.0), size=starts.size)
    for s, ln in zip(starts.tolist(), lengths.tolist()):
        mask[s:s + ln] = True
    return mask
