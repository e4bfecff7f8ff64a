"""The HIL bench: single runs, identification passes, campaigns, the oracle, targets, reports,
plots, tuning of the baselines, the bridge bench and the ``hil`` command's bench sub-commands.

May import everything above it: :mod:`hil.truth`, :mod:`hil.devices`, :mod:`hil.links`,
:mod:`hil.vehicle`, and :mod:`design`, :mod:`gnss`, :mod:`identification`.
"""
