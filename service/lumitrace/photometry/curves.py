"""The light distribution curves an engineer reads, drawn into matplotlib axes: the polar
curve and the Cartesian (linear angle) diagram of the C0-C180 and C90-C270 planes in
cd/klm of lamp flux, each with the files' standard error as a band (+- 1 sigma), the beam
(50%) and field (10%) angles marked and the peak named. The datasheet and the published
pictures draw the same curves.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from .grid import CGammaGrid

#: Planes drawn: (C of the right half, line style, colour, label, record key suffix).
PLANES = ((0.0, "-", "#c0392b", "C0 - C180", "c0_c180"),
          (90.0, "--", "#2c5aa0", "C90 - C270", "c90_c270"))
#: A beam narrower than this (deg, full angle) reads badly on a polar curve: the datasheet
#: adds the Cartesian diagram.
NARROW_BEAM_DEG = 60.0


def plane_curve(grid: CGammaGrid, c: float, per_klm: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(signed angle deg, cd/klm, sigma cd/klm) through a plane: gamma from the C + 180
    half (negative angles) through nadir to the C half (positive)."""
    g = grid.gamma
    right = grid.at(np.array([c]))[0] * per_klm
    left = grid.at(np.array([c + 180.0]))[0] * per_klm
    sig = grid.sigma if grid.sigma is not None else np.zeros_like(grid.candela)
    s_right = grid.at(np.array([c]), sig)[0] * per_klm
    s_left = grid.at(np.array([c + 180.0]), sig)[0] * per_klm
    ang = np.concatenate([-g[::-1], g[1:]])
    return (ang, np.concatenate([left[::-1], right[1:]]),
            np.concatenate([s_left[::-1], s_right[1:]]))


def _angle(figures: Mapping | None, key: str) -> float | None:
    v = None if figures is None else figures.get(key)
    return None if v is None or not np.isfinite(v) else float(v)


def is_narrow(figures: Mapping | None) -> bool:
    """Whether the beam is narrow enough to need the Cartesian diagram."""
    beams = [_angle(figures, f"beam_angle_{p[4]}") for p in PLANES]
    beams = [b for b in beams if b is not None]
    return bool(beams) and min(beams) < NARROW_BEAM_DEG


def draw_polar(ax, grid: CGammaGrid, lamp_lumens: float, figures: Mapping | None = None,
               title: str = "") -> None:
    """Draw the polar curve into polar axes ``ax``: nadir down, C0 and C90 on the right,
    the error band, the beam and field angles as rays, the peak as a dot."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    per_klm = 1000.0 / lamp_lumens if lamp_lumens > 0 else 1.0
    ax.set_theta_zero_location("S")
    ax.set_theta_direction(1)
    top = 0.0
    for c, style, colour, label, _ in PLANES:
        ang, r, s = plane_curve(grid, c, per_klm)
        theta = np.radians(ang) % (2 * np.pi)
        order = np.argsort(np.where(ang < 0, 360.0 + ang, ang), kind="stable")
        theta, r, s = theta[order], r[order], s[order]
        # closed through nadir: the C + 180 half ends just short of 360 deg, where the
        # C half began at 0
        theta = np.append(theta, theta[0] + 2 * np.pi)
        r, s = np.append(r, r[0]), np.append(s, s[0])
        ax.fill_between(theta, np.maximum(r - s, 0.0), r + s, color=colour, alpha=0.25,
                        lw=0)
        ax.plot(theta, r, style, lw=1.5, color=colour, label=label)
        top = max(top, float(np.nanmax(r + s)) if r.size else 0.0)
    ax.set_ylim(0.0, top * 1.05 if top > 0 else 1.0)
    for c, style, colour, label, key in PLANES:
        for what, ls in (("beam", (0, (4, 2))), ("field", (0, (1, 2)))):
            a = _angle(figures, f"{what}_angle_{key}")
            if a is None or top <= 0:
                continue
            for t in (a / 2, -a / 2):
                ax.plot([0, np.radians(t)], [0, top], ls=ls, lw=0.8, color=colour,
                        alpha=0.8)
    if figures is not None and figures.get("peak_intensity") and top > 0:
        pg = float(figures.get("peak_gamma") or 0.0)
        pc = float(figures.get("peak_c") or 0.0) % 360.0
        sign = -1.0 if 90.0 < pc < 270.0 else 1.0
        ax.plot([np.radians(sign * pg)], [figures["peak_intensity"] * per_klm], "o",
                ms=4, color="black", label=f"peak {figures['peak_intensity']:,.0f} cd")
    ax.set_thetagrids(np.arange(0, 360, 30),
                      [f"{int(a if a <= 180 else 360 - a)}°" for a in range(0, 360, 30)])
    ax.set_rlabel_position(100)
    ax.yaxis.set_major_locator(MaxNLocator(4))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:,.0f}"))
    ax.tick_params(axis="y", labelsize=7)
    ax.tick_params(axis="x", labelsize=8)
    if not top > 0:
        ax.text(0.5, 0.5, "no light leaves the luminaire", transform=ax.transAxes,
                ha="center", va="center", fontsize=11)
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: ""))
    ax.grid(True, lw=0.4, alpha=0.6)
    ax.set_title((title + "\n" if title else "") + "cd/klm; band: +-1 standard error; "
                 "rays: beam (dashed), field (dotted)", fontsize=8, parse_math=False)
    ax.legend(loc="lower left", bbox_to_anchor=(-0.12, -0.14), fontsize=7, frameon=False)


def draw_cartesian(ax, grid: CGammaGrid, lamp_lumens: float, figures: Mapping | None = None,
                   title: str = "") -> None:
    """Draw the Cartesian diagram into ``ax``: cd/klm over the signed angle from nadir
    in both planes, out to 1.5 field half-angles, with the error band and the beam and
    field angles as vertical lines."""
    per_klm = 1000.0 / lamp_lumens if lamp_lumens > 0 else 1.0
    fields = [_angle(figures, f"field_angle_{p[4]}") for p in PLANES]
    fields = [f for f in fields if f is not None]
    reach = min(180.0, 0.75 * max(fields)) if fields else 90.0
    reach = max(reach, 5.0)
    for c, style, colour, label, key in PLANES:
        ang, r, s = plane_curve(grid, c, per_klm)
        keep = np.abs(ang) <= reach + 1e-9
        ax.fill_between(ang[keep], np.maximum(r - s, 0.0)[keep], (r + s)[keep],
                        color=colour, alpha=0.25, lw=0)
        ax.plot(ang[keep], r[keep], style, lw=1.4, color=colour, label=label)
        for what, ls in (("beam", (0, (4, 2))), ("field", (0, (1, 2)))):
            a = _angle(figures, f"{what}_angle_{key}")
            if a is not None:
                for t in (-a / 2, a / 2):
                    ax.axvline(t, ls=ls, lw=0.8, color=colour, alpha=0.8)
    ax.set_xlim(-reach, reach)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("angle from nadir (deg): C180 / C270 left, C0 / C90 right", fontsize=8)
    ax.set_ylabel("cd/klm", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, lw=0.4, alpha=0.6)
    ax.legend(fontsize=7, frameon=False, loc="upper right")
    ax.set_title((title + "\n" if title else "") + "Cartesian diagram; band: +-1 standard "
                 "error; lines: beam (dashed), field (dotted)", fontsize=8, parse_math=False)
