"""gnss package."""
