"""Runs on fields: the oracle on a route, what a farmer sees (tracking per part, spacing), comparisons."""
