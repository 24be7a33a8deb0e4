"""EULUMDAT (.ldt) photometric files: writer and reader.

The files are ISO 8859-1 text, as EULUMDAT readers read them; each text field is one line
of at most its field's length (78 characters, the lamp type 24, the colour appearance 16,
the colour rendering group 6), cut there: see :func:`~.plain_text.one_line`.

Intensities are stored in cd/klm of lamp flux. The symmetry indicator says which C planes
hold data; for the C90-C270 symmetry (Isym 3) the planes run, as the standard's formula
``Mc1 = 3 Mc / 4 + 1, Mc2 = Mc1 + Mc / 2`` says, from C270 through C0 to C90.
"""
from __future__ import annotations

import datetime as _dt
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..atomic import write_text
from ..errors import LumitraceError
from .grid import CGammaGrid
from .plain_text import one_line

#: The character set EULUMDAT files are written and read in.
ENCODING = "latin-1"


def field(text: str, width: int = 78) -> str:
    """``text`` as an EULUMDAT text field of at most ``width`` characters."""
    return one_line(text, ENCODING, width)

ISYM = {"none": 0, "rotational": 1, "C0-C180": 2, "C90-C270": 3, "quadrant": 4}
ROOM_INDICES = (0.6, 0.8, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0)


def data_planes(isym: int, mc: int) -> tuple[int, int]:
    """1-based first and last C-plane indices holding data (``Mc1``, ``Mc2``)."""
    if isym == 0:
        return 1, mc
    if isym == 1:
        return 1, 1
    if isym == 2:
        return 1, mc // 2 + 1
    if isym == 3:
        mc1 = 3 * mc // 4 + 1
        return mc1, mc1 + mc // 2
    if isym == 4:
        return 1, mc // 4 + 1
    raise ValueError(f"symmetry indicator must be 0-4, got {isym}")


def plane_angles(isym: int, mc: int, dc: float) -> np.ndarray:
    """C angles (deg) of the planes holding data, in file order."""
    mc1, mc2 = data_planes(isym, mc)
    return np.array([((k - 1) % mc) * dc for k in range(mc1, mc2 + 1)], dtype=np.float64)


def direct_ratios(grid: CGammaGrid) -> list[float]:
    """Direct ratios for the standard room indices: the share of the downward flux of a
    regular array of these luminaires on the ceiling of a square room (side 2 k h, h the
    height above the work plane) that falls directly on the work plane."""
    g = grid.full()
    gam = g.gamma[g.gamma < 90.0]
    cd = g.candela[:, : len(gam)]
    edges = np.concatenate([[0.0], 0.5 * (gam[1:] + gam[:-1]), [90.0]])
    zone = np.cos(np.radians(edges[:-1])) - np.cos(np.radians(edges[1:]))
    dc = 2.0 * np.pi / len(g.c)
    flux = cd * zone[None, :] * dc  # lm per cell, (C, gamma)
    down = flux.sum()
    if down <= 0:
        return [0.0] * len(ROOM_INDICES)
    c = np.radians(g.c)[:, None]
    r = np.tan(np.radians(gam))[None, :]  # horizontal throw per unit height
    out = []
    for k in ROOM_INDICES:
        side = 2.0 * k
        fx = np.clip(1.0 - np.abs(r * np.cos(c)) / side, 0.0, None)
        fy = np.clip(1.0 - np.abs(r * np.sin(c)) / side, 0.0, None)
        out.append(float((flux * fx * fy).sum() / down))
    return out


def format_ldt(grid: CGammaGrid, lamp_lumens: float, name: str, dims_mm: dict,
               dff: float, lor: float, company: str = "lumitrace", report: str = "",
               dc: float = 5.0, number: str = "", file_name: str = "",
               lamp_type: str = "lumitrace emitters", colour: str = "", cri: str = "",
               watts: float = 0.0) -> str:
    """EULUMDAT text of a grid (cd) for lamps of ``lamp_lumens`` lm. ``dims_mm`` holds
    luminaire ``length``, ``width``, ``height`` and luminous area ``lum_length``,
    ``lum_width``, ``lum_height`` in mm (a width of 0: circular, the length its
    diameter); ``dff`` and ``lor`` are fractions; ``number`` the luminaire number,
    ``lamp_type``, ``colour`` (appearance, say "3000 K"), ``cri`` (colour rendering) and
    ``watts`` (wattage including ballast) the lamp set's data."""
    isym = ISYM[grid.symmetry]
    mc = int(round(360.0 / dc))
    cs = plane_angles(isym, mc, dc)
    per_klm = 1000.0 / lamp_lumens
    values = grid.at(cs) * per_klm
    ng = len(grid.gamma)
    steps = np.diff(grid.gamma)
    dg = float(steps[0]) if steps.size and np.allclose(steps, steps[0]) else 0.0
    f = lambda x: f"{x:.6g}"  # noqa: E731
    lines = [field(company), "1" if isym == 1 else "3", str(isym), str(mc), f(dc), str(ng),
             f(dg), field(report), field(name), field(number), field(file_name),
             field(f"{_dt.date.today().isoformat()} lumitrace"),
             f(dims_mm["length"]), f(dims_mm["width"]), f(dims_mm["height"]),
             f(dims_mm["lum_length"]), f(dims_mm["lum_width"])]
    lines += [f(dims_mm["lum_height"])] * 4
    lines += [f"{100.0 * dff:.2f}", f"{100.0 * lor:.2f}", "1", "0", "1", "1",
              field(lamp_type, 24), f(lamp_lumens), field(colour, 16), field(cri, 6),
              f(watts)]
    lines += [f"{v:.3f}" for v in direct_ratios(grid)]
    lines += [f(c) for c in np.arange(mc) * dc]
    lines += [f(g) for g in grid.gamma]
    lines += [f"{v:.4g}" for v in values.ravel()]
    return "\r\n".join(lines) + "\r\n"


def write_ldt(path: str | os.PathLike, grid: CGammaGrid, lamp_lumens: float, name: str,
              dims_mm: dict, dff: float, lor: float, **kw) -> Path:
    """Write an EULUMDAT file atomically (ISO 8859-1); see :func:`format_ldt`."""
    write_text(path, format_ldt(grid, lamp_lumens, name, dims_mm, dff, lor, **kw), ENCODING)
    return Path(path)


@dataclass
class LDTFile:
    """What an EULUMDAT file says; ``grid`` is in cd for the file's total lamp flux."""

    company: str
    ityp: int
    isym: int
    mc: int
    dc: float
    ng: int
    dg: float
    name: str
    dims_mm: dict
    dff: float
    lorl: float
    lamp_flux: float
    direct_ratios: list
    c_angles: np.ndarray
    gammas: np.ndarray
    cd_per_klm: np.ndarray
    grid: CGammaGrid


def parse_ldt(text: str, where: str = "LDT file") -> LDTFile:
    """Parse EULUMDAT text."""
    lines = [ln.strip() for ln in text.replace("\r\n", "\n").replace("\r", "\n").split("\n")]
    pos = 0

    def take() -> str:
        nonlocal pos
        if pos >= len(lines):
            raise LumitraceError(f"ends early, at line {pos + 1}", where=where)
        pos += 1
        return lines[pos - 1]

    def num(label: str) -> float:
        s = take()
        try:
            return float(s.replace(",", ".")) if s else 0.0
        except ValueError:
            raise LumitraceError(f"line {pos}: {label} is not a number: {s!r}",
                                 where=where) from None

    company = take()
    ityp, isym, mc = int(num("Ityp")), int(num("Isym")), int(num("Mc"))
    dc, ng, dg = num("Dc"), int(num("Ng")), num("Dg")
    take(), (name := take()), take(), take(), take()
    dims = {k: num(k) for k in ("length", "width", "height", "lum_length", "lum_width")}
    heights = [num("luminous height") for _ in range(4)]
    dims["lum_height"] = heights[0]
    dff, lorl, _, _ = num("DFF"), num("LORL"), num("conversion factor"), num("tilt")
    nsets = int(num("number of lamp sets"))
    lamp_flux = 0.0
    for _ in range(nsets):
        n_lamps = num("number of lamps")
        take()
        flux = num("lamp flux")
        take(), take()
        num("wattage")
        lamp_flux += flux if n_lamps >= 0 else flux  # negative count: absolute photometry
    drs = [num("direct ratio") for _ in range(10)]
    c_angles = np.array([num("C angle") for _ in range(mc)])
    gammas = np.array([num("gamma angle") for _ in range(ng)])
    mc1, mc2 = data_planes(isym, mc)
    nplanes = mc2 - mc1 + 1
    vals = np.array([num("intensity") for _ in range(nplanes * ng)]).reshape(nplanes, ng)
    cs = np.array([c_angles[(k - 1) % mc] for k in range(mc1, mc2 + 1)])
    cd = vals * lamp_flux / 1000.0
    sym = {v: k for k, v in ISYM.items()}[isym]
    if isym == 3:  # file order C270..C360/0..C90: store as C90..C270 (mirror image)
        order = np.argsort((180.0 - cs) % 360.0)
        cs_store = ((180.0 - cs) % 360.0)[order]
        grid = CGammaGrid(cs_store, gammas, cd[order], sym)
    elif isym == 0:
        grid = CGammaGrid(cs, gammas, cd, "none")
    else:
        grid = CGammaGrid(cs, gammas, cd, sym)
    return LDTFile(company, ityp, isym, mc, dc, ng, dg, name, dims, dff, lorl, lamp_flux, drs,
                   c_angles, gammas, vals, grid)


def read_ldt(path: str | os.PathLike) -> LDTFile:
    """Read an EULUMDAT file."""
    p = Path(path)
    try:
        text = p.read_text(encoding=ENCODING)
    except OSError as exc:
        raise LumitraceError(f"cannot read: {exc.strerror}", where=str(p)) from None
    return parse_ldt(text, where=str(p))
