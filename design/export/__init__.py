"""Exports of a controller file: JSON, a C header, CSV, a C folder with the step function."""
