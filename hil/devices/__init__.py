"""hil.devices package."""
