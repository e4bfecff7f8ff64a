"""hil package: the simulated tractor, the emulated devices, the tractor's runtime, commissioning and the bench."""

from importlib import metadata

#: The distribution whose version the commands print (pyproject.toml's ``name``).
DISTRIBUTION = "tractor-autosteer"


def toolkit_version() -> str:
    """The installed toolkit's version (pyproject.toml's ``version``), or ``"unknown"`` outside an installation."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return "unknown"
