"""IES LM-63 photometric files: written as LM-63-2019, read from 2019, 2002, 1995, 1991, 1986.

Type C photometry only on writing (vertical angles gamma from nadir, horizontal angles C
counter-clockwise from the luminaire's +X seen from above), TILT=NONE, units metres. The
horizontal angles follow the symmetry of the data: 0 (rotational), 0-90 (quadrant), 0-180
(mirror about the C0-C180 plane), 90-270 (mirror about the C90-C270 plane) or 0-360.
"""
from __future__ import annotations

import datetime as _dt
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..atomic import write_text
from ..errors import LumitraceError
from .grid import CGammaGrid
from .plain_text import one_line

#: LM-63-2019 file generation type (Table 2, ``1.ABCDE``: A accredited lab, B interpolated
#: angle set, C lumen scaled, D computer simulation, E undefined): 1.00010 is a computer
#: simulation (1.01000 would claim an unaccredited lab test with interpolated angles).
FILE_GENERATION_SIMULATION = 1.0001
_LINE = 240  # keep lines well inside the 256-character limit


#: Gap (deg) between a partial file's outermost angle and the zeros beyond it.
EDGE = 1e-3


@dataclass
class IESFile:
    """The content of an LM-63 file. ``candela`` is (len(horizontal), len(vertical)) cd,
    already multiplied by the candela multiplier and ballast factor."""

    version: str
    keywords: dict[str, str]
    lamps: int
    lumens_per_lamp: float
    multiplier: float
    vertical: np.ndarray
    horizontal: np.ndarray
    candela: np.ndarray
    photometric_type: int = 1
    units: int = 2
    width: float = 0.0
    length: float = 0.0
    height: float = 0.0
    ballast_factor: float = 1.0
    file_generation: float = FILE_GENERATION_SIMULATION
    input_watts: float = 0.0
    tilt: str = "NONE"
    extra: dict = field(default_factory=dict)

    def grid(self) -> CGammaGrid:
        """The type C distribution as a C-gamma grid over gamma 0-180, with its symmetry."""
        if self.photometric_type != 1:
            raise LumitraceError(f"photometric type {self.photometric_type} is not type C")
        h, v, cd = self.horizontal, self.vertical, self.candela
        # a file that covers part of the gammas has no light beyond them: zeros from a
        # hair (EDGE) past its last angle, so that neither interpolation nor the zones
        # between sample midpoints spread its outermost values over the rest
        if v[0] > 0.0:  # upper-hemisphere-only data: nothing below
            pre = [0.0] + ([v[0] - EDGE] if v[0] - EDGE > 0.0 else [])
            v = np.concatenate([pre, v])
            cd = np.hstack([np.zeros((len(h), len(pre))), cd])
        if v[-1] < 180.0:  # lower-hemisphere-only data: nothing above
            post = ([v[-1] + EDGE] if v[-1] + EDGE < 180.0 else []) + [180.0]
            v = np.concatenate([v, post])
            cd = np.hstack([cd, np.zeros((len(h), len(post)))])
        lo, hi = float(h[0]), float(h[-1])
        if len(h) == 1:
            sym = "rotational"
        elif lo == 0.0 and hi == 90.0:
            sym = "quadrant"
        elif lo == 0.0 and hi == 180.0:
            sym = "C0-C180"
        elif lo == 90.0 and hi == 270.0:
            sym = "C90-C270"
        elif lo == 0.0 and hi == 360.0:
            sym = "none"
        elif lo == 0.0 and hi < 360.0:
            sym = "none"  # 0..(360 - step): the 360 plane is implied
        else:
            raise LumitraceError(f"horizontal angles {lo:g}-{hi:g} are not a type C range")
        return CGammaGrid(np.asarray(h, float), np.asarray(v, float), np.asarray(cd, float), sym)


def _numbers(values, fmt: str) -> list[str]:
    """Values formatted and wrapped into lines shorter than the LM-63 limit."""
    lines, line = [], ""
    for v in values:
        s = fmt.format(v)
        if line and len(line) + 1 + len(s) > _LINE:
            lines.append(line)
            line = s
        else:
            line = f"{line} {s}" if line else s
    if line:
        lines.append(line)
    return lines


def keyword_lines(key: str, value: str) -> list[str]:
    """The lines of keyword ``key`` holding ``value``, as LM-63 defines them: one line of
    ASCII text (:func:`~.plain_text.one_line`), continued on ``[MORE]`` lines where it is
    longer than a line may be (cut between words, inside a word only where one word is
    longer than a line); none for a value that is empty as one line."""
    text = one_line(value, "ascii")
    lines, prefix = [], f"[{key}] "
    while text:
        room = _LINE - len(prefix)
        if len(text) <= room:
            lines.append(prefix + text)
            break
        cut = text.rfind(" ", 0, room + 1)
        cut = cut if cut > 0 else room
        lines.append(prefix + text[:cut].rstrip())
        text, prefix = text[cut:].lstrip(), "[MORE] "
    return lines


def format_ies(grid: CGammaGrid, lamp_lumens: float, width: float, length: float,
               height: float, keywords: dict[str, str] | None = None,
               input_watts: float = 0.0) -> str:
    """LM-63-2019 text of a type C grid (cd for lamps of ``lamp_lumens`` lm in total);
    luminous opening ``width`` (along C90), ``length`` (along C0), ``height`` in metres
    (negative width and length: a circular or elliptical opening, LM-63's Table 1);
    ``input_watts`` the luminaire's input power (W)."""
    today = _dt.date.today().isoformat()
    kw = {"TEST": "lumitrace photon tracing", "TESTLAB": "lumitrace (computer simulation)",
          "ISSUEDATE": today, "MANUFAC": "unknown"}
    kw.update({k: v for k, v in (keywords or {}).items() if one_line(v or "")})
    out = ["IES:LM-63-2019"]
    out += [line for k, v in kw.items() for line in keyword_lines(k, v)]
    out.append("TILT=NONE")
    out.append(f"1 {lamp_lumens:.6g} 1 {len(grid.gamma)} {len(grid.c)} 1 2 "
               f"{width:.4f} {length:.4f} {height:.4f}")
    out.append(f"1.0 {FILE_GENERATION_SIMULATION:.5f} {input_watts:.6g}")
    out += _numbers(grid.gamma, "{:.6g}")
    out += _numbers(grid.c, "{:.6g}")
    for row in grid.candela:
        out += _numbers(row, "{:.6g}")
    return "\r\n".join(out) + "\r\n"


def write_ies(path: str | os.PathLike, grid: CGammaGrid, lamp_lumens: float, width: float,
              length: float, height: float, keywords: dict[str, str] | None = None,
              input_watts: float = 0.0) -> Path:
    """Write an LM-63-2019 file atomically; see :func:`format_ies`."""
    write_text(path, format_ies(grid, lamp_lumens, width, length, height, keywords,
                                input_watts))
    return Path(path)


_TAGS = {"IES:LM-63-2019": "LM-63-2019", "IESNA:LM-63-2002": "LM-63-2002",
         "IESNA:LM-63-1995": "LM-63-1995", "IESNA91": "LM-63-1991"}


def parse_ies(text: str, where: str = "IES file") -> IESFile:
    """Parse LM-63 text of any version (1986 to 2019)."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    first = lines[0].strip().lstrip("\ufeff")
    version = _TAGS.get(first.upper().replace(" ", ""), None)
    start = 1 if version else 0
    version = version or "LM-63-1986"
    keywords: dict[str, str] = {}
    last = None
    i = start
    while i < len(lines) and not lines[i].strip().upper().startswith("TILT"):
        m = re.match(r"\s*\[([^\]]+)\]\s*(.*)", lines[i])
        if m:
            key, val = m.group(1).strip().upper(), m.group(2).strip()
            if key == "MORE" and last:
                keywords[last] += " " + val
            else:
                keywords[key] = val
                last = key
        i += 1
    if i == len(lines):
        raise LumitraceError("no TILT= line", where=where)
    tilt = lines[i].split("=", 1)[1].strip() if "=" in lines[i] else "NONE"
    tokens = " ".join(lines[i + 1:]).replace(",", " ").split()
    try:
        nums = [float(t) for t in tokens]
    except ValueError as exc:
        raise LumitraceError(f"not a number after TILT: {exc}", where=where) from None
    k = 0
    if tilt.upper() == "INCLUDE":
        n_pairs = int(nums[1])
        k = 2 + 2 * n_pairs
    try:
        lamps, lumens, mult, nv, nh, ptype, units, w, ln, h = nums[k:k + 10]
        ballast, gen, watts = nums[k + 10:k + 13]
        k += 13
        nv, nh = int(nv), int(nh)
        vertical = np.array(nums[k:k + nv])
        horizontal = np.array(nums[k + nv:k + nv + nh])
        cd = np.array(nums[k + nv + nh:k + nv + nh + nv * nh])
    except ValueError:
        raise LumitraceError("the photometric data section is incomplete", where=where) from None
    if cd.size != nv * nh or vertical.size != nv or horizontal.size != nh:
        raise LumitraceError(f"expected {nv} x {nh} candela values, found {cd.size}",
                             where=where)
    return IESFile(version=version, keywords=keywords, lamps=int(lamps), lumens_per_lamp=lumens,
                   multiplier=mult, vertical=vertical, horizontal=horizontal,
                   candela=cd.reshape(nh, nv) * mult * ballast, photometric_type=int(ptype),
                   units=int(units), width=w, length=ln, height=h, ballast_factor=ballast,
                   file_generation=gen, input_watts=watts, tilt=tilt)


def read_ies(path: str | os.PathLike) -> IESFile:
    """Read an LM-63 file (any version)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise LumitraceError(f"cannot read: {exc.strerror}", where=str(p)) from None
    return parse_ies(text, where=str(p))
