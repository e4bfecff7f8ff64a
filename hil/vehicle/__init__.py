"""hil.vehicle package."""
