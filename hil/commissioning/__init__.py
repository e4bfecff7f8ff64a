"""Commissioning a tractor from what was recorded on it: identification of its pass logs, the designs
certified on its models, and the report, with no simulator and no truth.

The bench's recipe (:mod:`hil.bench.commissioning.recipe`) drives the same steps on an emulated tractor and adds
its evaluation; this package imports nothing of the simulator, the emulated devices or the bench.
"""
