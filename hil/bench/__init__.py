"""hil.bench package."""
