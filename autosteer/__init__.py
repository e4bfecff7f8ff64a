"""autosteer: the foundation every package of the toolkit shares, and that imports nothing of the toolkit.

* :mod:`autosteer.checks` - one check for the numbers a user or a file gives (finite, in range, a
  refusal of one line in the caller's error class);
* :mod:`autosteer.cli` - the command-line conventions of every command (one parser class with
  close-match suggestions, deprecated spellings, seed lists and conditions);
* :mod:`autosteer.version` - the toolkit's version, as every command prints it.
* :mod:`autosteer.bounded` - bounded reading of every file the toolkit loads (size, JSON nesting depth,
  ``.npz`` members checked from their headers);
* :mod:`autosteer.atomic` - the one atomic writer (a file appears whole or not at all);
* :mod:`autosteer.errors` - the default errors of the readers.

``gnss`` and ``identification`` stand on it side by side, ``design`` and ``hil`` above them
(``.importlinter``).
"""
