"""Reference numbers of the 1997 paper (DESIGN section 2), in SI units.

Table 2: central controller experimental results, cross-track bias and 1-sigma in m,
per gear (nominal speed) and implement. Source: ``shared/seed/000_c5362e991dd20cb6.txt``.
"""

from __future__ import annotations

from types import MappingProxyType

#: (implement, gear) -> (bias m, 1-sigma m)
TABLE2 = MappingProxyType({
    ("none", 5): (0.009, 0.032), ("disker", 5): (0.004, 0.023), ("ripper", 5): (0.004, 0.027),
    ("none", 7): (-0.002, 0.043), ("disker", 7): (0.007, 0.046), ("ripper", 7): (0.007, 0.066),
    ("none", 9): (-0.001, 0.066), ("disker", 9): (0.035, 0.064), ("ripper", 9): (-0.010, 0.043),
    ("none", 11): (0.007, 0.087), ("disker", 11): (0.060, 0.107), ("ripper", 11): (0.012, 0.075),
    ("none", 13): (-0.001, 0.092), ("disker", 13): (0.085, 0.127), ("ripper", 13): (0.075, 0.088),
})

#: An expert human driver with a hitched bedder: 1-sigma, m.
EXPERT_DRIVER_SIGMA = 0.127
