"""The luminaire's geometry as an L3D container (the geometry format of GLDF, ISO 7127).

An L3D file is a zip holding ``structure.xml`` and one folder per model, named by the id of
its ``GeometryFileDefinition``, with the model as a Wavefront OBJ (one object per file).
The luminaire is one model (one top-level geometry, as readers such as l3d-rs expect),
its OBJ one object with a group per part of the stage (a gprim), in metres in the
photometric frame (x along C0, y along C90, z up, as L3D expects: a light emitting object
with no rotation emits down, -z). The light emitting object is the measured luminous
opening, where the light leaves the luminaire (the photometric centre of the files): a
circle or a rectangle of the opening's size at its centre.
"""
from __future__ import annotations

import io
import re
import zipfile
from datetime import datetime, timezone

import numpy as np

from .. import __version__
from ..photometry.plain_text import one_line
from .xml_text import xml_text

#: The L3D format version written (``FormatVersion``), as the schema it validates against.
FORMAT_VERSION = (0, 11)
#: ``partName`` of the light emitting object: what a GLDF variant's
#: ``EmitterObjectExternalName`` names.
EMITTER_PART = "leo_opening"
#: Id (and folder, file and part name) of the one model.
MODEL_ID = "luminaire"


def part_id(path: str, taken: set[str]) -> str:
    """An NCName for a prim path, unique among ``taken`` (letters, digits, underscores,
    starting with a letter), e.g. ``/Luminaire/Reflector`` -> ``Reflector``."""
    base = re.sub(r"[^A-Za-z0-9_]", "_", path.rstrip("/").rsplit("/", 1)[-1]) or "part"
    if not base[0].isalpha():
        base = "p" + base
    name, k = base, 1
    while name in taken or name in (EMITTER_PART, MODEL_ID):
        k += 1
        name = f"{base}{k}"
    taken.add(name)
    return name


def obj_text(parts: list[tuple[str, str, np.ndarray]], name: str) -> str:
    """A Wavefront OBJ of the ``parts`` (id, prim path, triangles (T, 3, 3) m): one object
    ``name``, a group per part, vertices shared within a part."""
    lines = [f"# lumitrace {__version__}: the parts of {one_line(name, 'utf-8')}, metres",
             f"o {MODEL_ID}"]
    faces_out, base = [], 0
    for pid, path, tri in parts:
        pts = np.asarray(tri, dtype=np.float64).reshape(-1, 3)
        uniq, inverse = np.unique(np.round(pts, 9), axis=0, return_inverse=True)
        faces = inverse.reshape(-1, 3) + 1 + base
        keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & \
            (faces[:, 0] != faces[:, 2])  # triangles collapsed by the rounding
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in uniq]
        faces_out += [f"# {path}", f"g {pid}"] + [f"f {a} {b} {c}" for a, b, c in faces[keep]]
        base += len(uniq)
    return "\n".join(lines + faces_out) + "\n"


def _vector(tag: str, v=(0.0, 0.0, 0.0)) -> str:
    return f'<{tag} x="{v[0]:.9g}" y="{v[1]:.9g}" z="{v[2]:.9g}"/>'


def l3d_parts(scene) -> list[tuple[str, str, np.ndarray]]:
    """(part id, prim path, triangles in the photometric frame, m) of every part with
    triangles. The frame's origin is the world origin, its axes (C0, C90, up)."""
    axes = np.asarray(scene.photometric_axes)  # rows C0, C90, up in world axes
    taken: set[str] = set()
    out = []
    for path, (tri, _) in scene.part_geometry().items():
        if len(tri):
            out.append((part_id(path, taken), path, np.asarray(tri) @ axes.T))
    return out


def structure_xml(parts: list[tuple[str, str, np.ndarray]], opening, name: str,
                  when: datetime | None = None) -> str:
    """``structure.xml``: the one model of all ``parts``, the luminous opening its light
    emitting object (a circle where the opening is round)."""
    when = when or datetime.now(timezone.utc)
    centre = tuple(float(x) for x in opening.centre)
    if opening.round:
        shape = f'<Circle diameter="{0.5 * (opening.length + opening.width):.9g}"/>'
    else:
        shape = f'<Rectangle sizeX="{opening.length:.9g}" sizeY="{opening.width:.9g}"/>'
    h = opening.height
    heights = f'<LuminousHeights c0="{h:.9g}" c90="{h:.9g}" c180="{h:.9g}" c270="{h:.9g}"/>'
    leo = (f'<LightEmittingObjects><LightEmittingObject partName="{EMITTER_PART}">'
           f'{_vector("Position", centre)}{_vector("Rotation")}{shape}{heights}'
           '</LightEmittingObject></LightEmittingObjects>')
    major, minor = FORMAT_VERSION
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<Luminaire xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">'
            f'<Header><Name>{xml_text(name)}</Name>'
            f'<Description>{len(parts)} parts of the USD stage (groups of the OBJ): '
            f'{xml_text(", ".join(path for _, path, _ in parts))}; metres, photometric frame '
            '(x C0, y C90, z up)</Description>'
            f'<CreatedWithApplication>{xml_text(f"lumitrace {__version__}")}'
            '</CreatedWithApplication>'
            f'<CreationTimeCode>{when.strftime("%Y-%m-%dT%H:%M:%S")}</CreationTimeCode>'
            f'<FormatVersion major="{major}" minor="{minor}"/></Header>'
            f'<GeometryDefinitions><GeometryFileDefinition id="{MODEL_ID}" '
            f'filename="{MODEL_ID}.obj" units="m"/></GeometryDefinitions>'
            f'<Structure><Geometry partName="{MODEL_ID}">{_vector("Position")}'
            f'{_vector("Rotation")}<GeometryReference geometryId="{MODEL_ID}"/>{leo}'
            '</Geometry></Structure></Luminaire>\n')


def l3d_bytes(scene, opening, name: str, when: datetime | None = None) -> bytes:
    """The L3D container (zip bytes) of ``scene``'s parts and the luminous ``opening``.
    A scene without triangles (bare lights) gets one small box at the opening so the
    container has the geometry L3D requires."""
    parts = l3d_parts(scene)
    if not parts:
        parts = [("opening", "", _opening_box(opening))]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("structure.xml", structure_xml(parts, opening, name, when))
        z.writestr(f"{MODEL_ID}/{MODEL_ID}.obj", obj_text(parts, name))
    return buf.getvalue()


def _opening_box(opening) -> np.ndarray:
    """Triangles (12, 3, 3) of a flat box the size of the opening, its bottom at the
    opening's centre (a stand-in geometry)."""
    lx, ly = max(opening.length, 1e-3) / 2, max(opening.width, 1e-3) / 2
    c = np.asarray(opening.centre, dtype=np.float64)
    corners = np.array([[x, y, z] for z in (0.0, 0.01) for y in (-ly, ly) for x in (-lx, lx)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
             (1, 5, 7, 3)]
    tri = [(corners[a], corners[b], corners[c_]) for q in quads
           for a, b, c_ in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]
    return np.array(tri) + c

