"""hil.vehicle.bridge package."""
