"""Writing the luminaire's exit rays (traced by :mod:`lumitrace.trace.exit_rays`) as an
IES TM-25 ray file, over nothing but a ray file lumitrace wrote for the same stage."""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import LumitraceError
from ..scene import Scene
from ..tm25 import RayFile, header_texts, write_tm25

#: The most rays a file may hold by default (28 bytes each: 560 MB).
MAX_RAYS = 20_000_000


def claim_ray_file(path: str | os.PathLike, scene: Scene) -> None:
    """Refuse a ray file path that the stage reads (its own layers, a light's profile or
    rays) or that holds a file other than the exit rays lumitrace wrote for this stage."""
    path = Path(path)
    if os.path.realpath(path) in scene.input_files():
        raise LumitraceError("is a file the stage reads: the ray file would replace it; "
                             "name another (--out)", str(path))
    if not os.path.lexists(path):
        return
    texts = header_texts(path) if path.is_file() and not path.is_symlink() else None
    stage = os.path.basename(scene.stage_path)
    if texts is None or not texts[3].startswith("lumitrace ") or texts[8] != stage:
        raise LumitraceError(f"exists and is not a ray file lumitrace wrote for {stage}: "
                             "move it away or name another (--out)", str(path))


def check_ray_count(path: str | os.PathLike, photons: int, max_rays: int = MAX_RAYS) -> None:
    """Refuse, before tracing, a ray file that could hold more than ``max_rays`` rays."""
    if photons > max_rays:
        raise LumitraceError(f"{photons} photons could make more than the {max_rays} rays a "
                             "ray file may hold (28 bytes each); trace fewer", str(path))


def write_ray_file(path: str | os.PathLike, rays: RayFile, scene: Scene) -> None:
    """Write traced exit rays to ``path`` (TM-25-13), a path :func:`claim_ray_file`
    allows for ``scene``."""
    claim_ray_file(path, scene)
    write_tm25(path, rays)
