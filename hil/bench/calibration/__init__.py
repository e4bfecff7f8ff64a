"""Calibration of the bench against the paper's Table 2 (``hil calibrate``): the search, the
pipeline that re-runs the paper's method, and its report. Imports :mod:`hil.bench` and below.
"""
