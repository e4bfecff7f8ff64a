"""What runs on the tractor: the vehicle loop, the steering-bridge protocol and driver, the host's
wheel-angle calibration and ``hil drive``.

Imports :mod:`design`, :mod:`gnss`, :mod:`identification` and :mod:`hil.links` only: nothing of the
simulator, the emulated devices or the bench.
"""
