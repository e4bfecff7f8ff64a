"""The toolkit's version, as the commands print it (``--version``).

One function for the ``gnss``, ``identification``, ``design`` and ``hil`` commands.
"""

from __future__ import annotations

from importlib import metadata

__all__ = ["DISTRIBUTION", "toolkit_version"]

#: The distribution whose version the commands print (pyproject.toml's ``name``).
DISTRIBUTION = "tractor-autosteer"


def toolkit_version() -> str:
    """The installed toolkit's version (pyproject.toml's ``version``).

    Returns
    -------
    str
        The version, or ``"unknown"`` when the toolkit runs from a source tree that was never installed.
    """
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return "unknown"
