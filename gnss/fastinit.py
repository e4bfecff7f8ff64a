"""Building frozen dataclass records without their generated ``__init__`` (hot paths only).

A frozen dataclass's ``__init__`` stores each field through ``object.__setattr__`` (the
class's own ``__setattr__`` refuses), about 0.1 microsecond a field. The GNSS front-end
builds a few such records for every message and every loop tick; :func:`positional_maker`
gives a function that builds the same record from its field values in field order, storing
each one directly (in the slot, or the instance dictionary). The result is equal to
``cls(*values)`` in every respect; only classes whose ``__init__`` does nothing but store the
fields qualify (no ``__post_init__``, no ``InitVar``, every field in ``__init__``).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

__all__ = ["positional_maker"]


def positional_maker(cls: type) -> Callable[..., Any]:
    """``make(*values)`` equal to ``cls(*values)`` (all fields, in field order), for a frozen dataclass.

    Raises
    ------
    TypeError
        ``cls`` is not a frozen dataclass whose ``__init__`` only stores its fields.
    """
    if not dataclasses.is_dataclass(cls) or not isinstance(cls, type):
        raise TypeError(f"positional_maker needs a dataclass type, got {cls!r}")
    params = cls.__dataclass_params__
    fields = dataclasses.fields(cls)
    if not params.frozen or hasattr(cls, "__post_init__") or not all(f.init for f in fields) \
            or len(fields) != len(cls.__dataclass_fields__):
        raise TypeError(f"{cls.__name__}: only a frozen dataclass whose __init__ stores every field and "
                        "nothing else can be built without its __init__")
    names = [f.name for f in fields]
    args = ", ".join(f"v{i}" for i in range(len(names)))
    env: dict[str, Any] = {"_new": object.__new__, "_cls": cls}
    lines = [f"def make({args}):", "    o = _new(_cls)"]
    if "__slots__" in cls.__dict__:
        for i, name in enumerate(names):
            env[f"_s{i}"] = getattr(cls, name).__set__   # the slot's member descriptor
            lines.append(f"    _s{i}(o, v{i})")
    else:
        lines.append("    o.__dict__.update(" + ", ".join(f"{n}=v{i}" for i, n in enumerate(names)) + ")")
    lines.append("    return o")
    exec(compile("\n".join(lines) + "\n", f"<positional_maker {cls.__qualname__}>", "exec"), env)
    make = env["make"]
    make.__doc__ = f"{cls.__name__}(*values) without its __init__ (see gnss.fastinit)."
    return make
