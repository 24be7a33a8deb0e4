"""Pictures of a distribution: the polar light distribution curve and the photometric solid.

The polar curve is the classic datasheet diagram: intensities in cd/klm of lamp flux in the
C0-C180 plane (solid) and the C90-C270 plane (dashed), nadir (gamma = 0) at the bottom,
C0 and C90 on the right (drawn by :mod:`.curves`). The photometric solid is the surface
r = I(direction) drawn around the luminaire's own geometry in false colour with a candela
scale, rendered offscreen with pyvista.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np

from ..atomic import atomic_path
from ..scene import Scene, point_bounds
from . import frame
from .grid import CGammaGrid


def polar_diagram(path: str | os.PathLike, grid: CGammaGrid, lamp_lumens: float,
                  title: str = "", figures: Mapping | None = None) -> Path:
    """Write the polar light distribution curve (PNG) of ``grid`` (cd), with its error
    band and, given the record's ``figures``, the beam and field angles and the peak
    (see :func:`lumitrace.photometry.curves.draw_polar`)."""
    from ..pyplot import pyplot

    plt = pyplot()

    from .curves import draw_polar

    fig = plt.figure(figsize=(6, 6.4), dpi=120)
    draw_polar(fig.add_subplot(projection="polar"), grid, lamp_lumens, figures, title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)


def solid_points(grid: CGammaGrid, scene: Scene) -> tuple:
    """The photometric solid of ``grid`` around ``scene``'s geometry, as its picture draws
    it: points (C, gamma, 3), their candela (C, gamma) and the luminaire's triangles."""
    full = grid.full()
    cs = np.append(full.c, 360.0)
    cd = np.vstack([full.candela, full.candela[:1]])
    cc, gg = np.meshgrid(cs, full.gamma, indexing="ij")
    d = frame.directions(cc, gg, scene.up_axis, frame.luminaire_rotation(scene))
    tri = np.asarray(scene.triangles)
    if tri.size:
        lo, hi = point_bounds(tri)
        center, size = 0.5 * (lo + hi), float((hi - lo).max())
    else:
        center, size = np.zeros(3), 0.1
    peak = float(cd.max()) or 1.0
    pts = center + d * (cd / peak * 1.5 * size)[..., None]
    return pts, cd, tri


def photometric_solid(path: str | os.PathLike, grid: CGammaGrid, scene: Scene,
                      title: str = "", job: tuple | None = None) -> Path:
    """Write a picture (PNG) of the photometric solid around the luminaire geometry: the
    renderer's drawing of it when ``job`` (from :func:`submit_solid`) succeeds, else drawn
    here (with matplotlib where VTK crashed the renderer: it would crash this process)."""
    from .solid_render import draw_solid, vtk_crashed

    r = job[0] if job is not None else None
    if r is not None and r.wait(job[1]):
        return Path(path)
    pts, cd, tri = solid_points(grid, scene)
    if vtk_crashed():
        return _solid_matplotlib(path, pts, cd, tri, title)
    try:
        return draw_solid(path, pts, cd, tri, scene.up_axis, title)
    except Exception:  # no working offscreen OpenGL: draw it with matplotlib instead
        return _solid_matplotlib(path, pts, cd, tri, title)


def submit_solid(path: str | os.PathLike, grid: CGammaGrid, scene: Scene,
                 title: str = "") -> tuple | None:
    """Hand the solid's picture to this process's renderer (started by
    :func:`~lumitrace.photometry.solid_render.start_renderer`), which draws it while this
    process goes on: (the renderer, its job), for :func:`photometric_solid`, or None
    without a renderer."""
    from .solid_render import renderer

    r = renderer()
    if r is None:
        return None
    pts, cd, tri = solid_points(grid, scene)
    job = r.submit(path, pts, cd, tri, scene.up_axis, title)
    return None if job is None else (r, job)


def _solid_matplotlib(path, pts, cd, tri, title) -> Path:
    from ..pyplot import pyplot

    plt = pyplot()

    fig = plt.figure(figsize=(6, 6), dpi=120)
    ax = fig.add_subplot(projection="3d")
    from matplotlib import cm
    from matplotlib.colors import Normalize

    norm = Normalize(0.0, float(cd.max()) or 1.0)
    ax.plot_surface(pts[..., 0], pts[..., 1], pts[..., 2], facecolors=cm.inferno(norm(cd)),
                    alpha=0.5, linewidth=0.1)
    fig.colorbar(cm.ScalarMappable(norm, "inferno"), ax=ax, shrink=0.6,
                 label="intensity (cd)")
    if tri.size:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        ax.add_collection3d(Poly3DCollection(tri, facecolor="#7f8c8d", edgecolor="none"))
    ax.set_title(title, fontsize=9, parse_math=False)  # a name's "$" is no maths
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)


def colour_diagram(path: str | os.PathLike, col, title: str = "") -> Path:
    """Write the colour over angle (PNG): u', v' and CCT over gamma (all round, with their
    standard errors), and every cell's u'v' on the CIE 1976 diagram with the spectral
    locus, the Planckian locus and the beam's Delta u'v' circle."""
    from ..pyplot import pyplot

    plt = pyplot()

    from ..scene.spectra import observer

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 5.0), dpi=110)
    g, uv, sig = col.gamma, col.ring_uv, col.ring_sigma
    lit = np.isfinite(uv).all(axis=0) & (col.ring_xyz[1] > 0)
    mean = np.asarray(col.mean_uv if np.isfinite(col.mean_uv).all()
                      else np.nanmean(uv[:, lit], axis=1))
    for k, (name, colour) in enumerate((("u'", "#c0392b"), ("v'", "#2c5aa0"))):
        left.errorbar(g[lit], 1000.0 * (uv[k][lit] - mean[k]), yerr=1000.0 * sig[lit],
                      fmt="o-", ms=3, lw=1.2, color=colour, capsize=2,
                      label=f"{name} - {mean[k]:.4f}")
    left.axhline(0.0, color="#999999", lw=0.6)
    left.set_xlabel("gamma (deg), all C")
    left.set_ylabel("chromaticity from the beam's mean (x 1/1000, CIE 1976)")
    left.grid(True, lw=0.4, alpha=0.6)
    twin = left.twinx()
    twin.plot(g[lit], col.ring_cct[lit], "s--", ms=3, lw=1, color="#555555", label="CCT")
    twin.set_ylabel("CCT (K)")
    lines = left.get_legend_handles_labels()
    more = twin.get_legend_handles_labels()
    left.legend(lines[0] + more[0], lines[1] + more[1], fontsize=8, frameon=False,
                loc="best")
    left.set_title("colour over gamma (standard errors as bars)", fontsize=10)
    # the CIE 1976 diagram: spectral locus, Planckian locus, the cells' chromaticities
    cmf = observer()
    locus = cmf / np.maximum(cmf.sum(axis=1, keepdims=True), 1e-12)
    d = cmf[:, 0] + 15 * cmf[:, 1] + 3 * cmf[:, 2]
    lu, lv = 4 * cmf[:, 0] / d, 9 * cmf[:, 1] / d
    keep = np.isfinite(lu) & np.isfinite(lv) & (locus[:, 1] > 0)
    right.plot(np.append(lu[keep], lu[keep][0]), np.append(lv[keep], lv[keep][0]), "k-", lw=0.8)
    temps = np.linspace(1500.0, 20000.0, 80)
    planck = np.array([_planck_uv(t) for t in temps])
    right.plot(planck[:, 0], planck[:, 1], "-", color="#888888", lw=0.8, label="Planckian")
    cells = np.isfinite(col.uv).all(axis=0) & (col.xyz[1] > 0)
    weight = col.xyz[1][cells] / col.xyz[1][cells].max()
    right.scatter(col.uv[0][cells], col.uv[1][cells], s=4 + 30 * weight, c=weight,
                  cmap="viridis", label="cells (size: intensity)")
    if np.isfinite(col.uniformity):
        circle = plt.Circle(col.mean_uv, col.uniformity, fill=False, color="#c0392b", lw=1)
        right.add_patch(circle)
        span = max(0.02, 3 * col.uniformity)
        right.set_xlim(col.mean_uv[0] - span, col.mean_uv[0] + span)
        right.set_ylim(col.mean_uv[1] - span, col.mean_uv[1] + span)
    right.set_aspect("equal")
    right.set_xlabel("u'")
    right.set_ylabel("v'")
    right.grid(True, lw=0.4, alpha=0.6)
    right.legend(fontsize=8, frameon=False, loc="upper right")
    cct, duv = col.total["cct_K"], col.total["duv"]
    right.set_title(f"CIE 1976 u'v' of every cell: CCT {cct:.0f} K, Duv {duv:+.4f}\n"
                    f"beam Delta u'v' {col.uniformity:.4f} (circle; noise {col.noise:.5f})",
                    fontsize=9)
    fig.suptitle(title, fontsize=10, parse_math=False)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)


def _planck_uv(t: float) -> tuple[float, float]:
    """u'v' of a Planckian radiator of ``t`` K (on the spectral grid)."""
    from ..scene.spectra import WAVELENGTHS, observer

    lam = WAVELENGTHS * 1e-9
    spd = 1.0 / (lam ** 5 * np.expm1(1.4387768775e-2 / (lam * t)))
    x, y, z = spd @ observer()
    d = x + 15 * y + 3 * z
    return 4 * x / d, 9 * y / d
