"""hil.truth package."""
