"""Commissioning a tractor on the bench: the recipe, its designs and trials, its report, campaigns of tractors."""
