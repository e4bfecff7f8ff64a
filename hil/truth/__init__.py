"""The simulated tractor: parameters, conditions, vehicle equations, steering and sensor,
disturbances, noise, GPS errors and the simulator that integrates them.

Imports nothing else of :mod:`hil` (only :mod:`hil.errors`) and nothing of the toolkit's other
packages: the truth knows nothing of the devices, the vehicle loop or the bench.
"""
