"""Export a linear controller file for the vehicle computer: JSON (canonical), a C header, CSV, or C99.

``c`` writes a directory with a dependency-free C99 step function and test vectors
(:mod:`design.export.c_code`).
The C header holds plain ``static const double`` arrays in row-major order with
their dimensions, the sample time, the normalisation of each output and the file's
checksum in comments; the CSV lists one matrix entry per row (``matrix,row,col,value``)
after ``#`` comment lines with the same information. Numbers are written with 17
significant digits so they read back exactly. Text from the file (its name, the outputs'
units) is checked before it is written (:func:`comment_text`); every output is written
atomically.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from design.core.errors import ControllerFileError, DesignInputError
from design.export.c_code import export_c, safe_name
from design.files.atomic import write_text_atomically
from design.files.envelope import read_json
from design.files.linear import ControllerFile, from_body
from design.files.mpc import mpc_from_body

FORMATS = ("json", "c-header", "csv", "c")
MATRICES = ("Ac", "Bc", "Cc", "Dc", "Ec", "X0")


def _ident(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9]", "_", name).upper()
    return s if s and not s[0].isdigit() else f"C_{s}"


def comment_text(line: str) -> str:
    """``line`` if it can stand in a C block comment and a CSV ``#`` line: printable ASCII without
    ``*/``, ``/*`` or a line break. Every text of the file that reaches an export passes through
    here, after the readers' own checks (:data:`design.files.linear.UNITS_PATTERN`, :func:`safe_name`).

    Raises
    ------
    ControllerFileError
        Naming the text; nothing is exported.
    """
    if not all(" " <= ch <= "~" for ch in line) or "*/" in line or "/*" in line:
        raise ControllerFileError(f"text {line[:80]!r} cannot be exported: expected printable ASCII without "
                                  "'*/', '/*' or a line break; correct the controller file")
    return line


def _header_lines(spec: ControllerFile, checksum: str) -> list[str]:
    c = spec.compensator
    outs = ", ".join(f"{o.name}{'/speed' if o.normalization == 'speed' else ''} [{o.units}]" for o in spec.outputs)
    return [comment_text(line) for line in (
            f"controller {safe_name(spec.name)}: linear compensator, schema design-controller/1",
            f"checksum {checksum}",
            f"dt = {c.dt!r} s; states nc = {c.order}; outputs q = {c.n_measurements}; commands m = 1",
            f"y (in order) = {outs}; speed floored at {spec.speed_min!r} m/s",
            "then y clipped to +-(" + ", ".join("none" if c is None else repr(c) for c in spec.output_clip) + ")",
            "u = steering-rate command [rad/s], clipped to +-" + repr(spec.rate_limit),
            "xc[k+1] = Ac xc[k] + Bc y[k] + Ec (u_applied[k] - u[k]);  u[k] = Cc xc[k] + Dc y[k]",
            "on the first step after an engage: xc = X0 y[k] (bumpless engage)")]


def to_c_header(spec: ControllerFile, checksum: str) -> str:
    """C header text (see module docstring)."""
    p = _ident(spec.name)
    c = spec.compensator
    lines = ["/* " + line + " */" for line in _header_lines(spec, checksum)]
    lines += [f"#ifndef {p}_CONTROLLER_H", f"#define {p}_CONTROLLER_H", "",
              f"#define {p}_DT {c.dt!r}", f"#define {p}_NC {c.order}", f"#define {p}_NY {c.n_measurements}",
              f"#define {p}_RATE_LIMIT {spec.rate_limit!r}", f"#define {p}_SPEED_MIN {spec.speed_min!r}", ""]
    for o_i, o in enumerate(spec.outputs):
        lines.append(f"#define {p}_Y{o_i}_DIVIDE_BY_SPEED {1 if o.normalization == 'speed' else 0}  /* {o.name} */")
        clip = spec.output_clip[o_i]
        lines.append(f"#define {p}_Y{o_i}_CLIP {'0 /* none */' if clip is None else repr(clip)}")
    lines.append("")
    for name in MATRICES:
        m = getattr(c, name)
        vals = ", ".join(format(float(v), ".17g") for v in m.ravel()) or "0"
        size = max(m.size, 1)
        lines.append(f"/* {name}: {m.shape[0]} x {m.shape[1]}, row-major */")
        lines.append(f"static const double {p}_{name.upper()}[{size}] = {{{vals}}};")
    lines += ["", f"#endif /* {p}_CONTROLLER_H */", ""]
    return "\n".join(lines)


def to_csv(spec: ControllerFile, checksum: str) -> str:
    """CSV text (see module docstring)."""
    lines = ["# " + line for line in _header_lines(spec, checksum)]
    lines.append("matrix,row,col,value")
    for name in MATRICES:
        m = getattr(spec.compensator, name)
        for (i, j), v in np.ndenumerate(m):
            lines.append(f"{name},{i},{j},{float(v):.17g}")
    return "\n".join(lines) + "\n"


def _checked(path, read):
    try:
        return read()
    except (ControllerFileError, DesignInputError) as exc:
        raise ControllerFileError(f"{path}: {exc}") from None


def export_controller(path: str | Path, fmt: str, out: str | Path | None = None) -> str:
    """Read and check a controller file, render it in ``fmt``, write ``out`` if given, return the text.

    The file is read with every check of :func:`design.files.load.load_controller`: a
    controller whose certificate is missing, failed or made for other matrices, or whose
    limits lie outside their physical ranges, is refused and nothing is written.
    ``fmt="c"`` writes a directory (:mod:`design.export.c_code`) and needs ``out``.

    Raises
    ------
    ControllerFileError
        The file fails a check.
    DesignInputError
        Unknown format, a format the kind does not support, or ``c`` without ``out``.
    """
    if fmt not in FORMATS:
        raise DesignInputError(f"format must be one of {FORMATS}, got {fmt!r}")
    body = read_json(path)
    if isinstance(body, dict) and body.get("kind") == "mpc":
        if fmt != "json":
            raise DesignInputError(f"{path} is an MPC controller: it is exported as JSON (model, weights, limits, "
                                   "horizon and solver for the vehicle's MPC); c-header, csv and c hold a linear "
                                   "compensator only")
        _checked(path, lambda: mpc_from_body(body, dt=None))
        text = json.dumps(body, indent=1) + "\n"          # as read and checked (a signature kept)
        _write(out, text)
        return text
    spec = _checked(path, lambda: from_body(body, dt=None))
    checksum = body["checksum"]
    if fmt == "c":
        if out is None:
            raise DesignInputError("--format c writes a directory of C sources: give --out DIR")
        files = export_c(spec, body["certificate"], checksum, out)
        return "\n".join(str(f) for f in files) + "\n"
    if fmt == "json":
        text = json.dumps(body, indent=1) + "\n"          # as read and checked (a signature kept)
    elif fmt == "c-header":
        text = to_c_header(spec, checksum)
    else:
        text = to_csv(spec, checksum)
    _write(out, text)
    return text


def _write(out: str | Path | None, text: str) -> None:
    """Write ``text`` to ``out`` atomically (unless None): the old file or the new one, never a part."""
    if out is None:
        return
    try:
        write_text_atomically(out, text)
    except OSError as exc:
        raise DesignInputError(f"cannot write {out} ({exc.strerror or exc}); it was left as it was") from None
