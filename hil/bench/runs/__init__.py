"""Closed-loop runs (on an AB line or a field's route), identification passes, campaigns, the oracle, targets and comparison reports."""
