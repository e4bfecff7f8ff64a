"""Emulated devices around the simulated tractor: the plant they share, the emulated steering
bridge firmware and GPS receivers, faults, and the emulated tractor on pseudo-terminals.

Imports :mod:`hil.truth`, :mod:`hil.links` and the wire protocols of :mod:`hil.vehicle.bridge`.
"""
