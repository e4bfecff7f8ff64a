"""hil package: the simulated tractor, the emulated devices, the tractor's runtime, commissioning and the bench."""
