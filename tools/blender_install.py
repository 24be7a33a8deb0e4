"""Install the lumitrace add-on into Blender, enable it and save the preferences::

    blender --background --python tools/blender_install.py [-- --link]

(or ``.venv-blender/bin/python tools/blender_install.py`` for Blender as a Python module).
It copies ``service/lumitrace_blender`` into Blender's user add-ons folder, replacing an
older copy; ``--link`` links it there instead, so that it follows this checkout. Blender's
``BLENDER_USER_RESOURCES`` chooses another user folder, as it does for Blender itself.
"""
from __future__ import annotations

import os
import shutil
import sys

import bpy
import addon_utils  # noqa: E402, I001  (on the path once bpy is imported)

SOURCE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                      "service", "lumitrace_blender")
NAME = "lumitrace_blender"


def install(link: bool = False) -> str:
    """Put the add-on in the user add-ons folder and enable it; returns where it is."""
    folder = bpy.utils.user_resource("SCRIPTS", path="addons", create=True)
    target = os.path.join(folder, NAME)
    if os.path.islink(target) or os.path.isfile(target):
        os.unlink(target)
    elif os.path.isdir(target):
        shutil.rmtree(target)
    if link:
        os.symlink(SOURCE, target, target_is_directory=True)
    else:
        shutil.copytree(SOURCE, target, ignore=shutil.ignore_patterns("__pycache__"))
    bpy.utils.refresh_script_paths()  # a user add-ons folder made just now
    addon_utils.modules_refresh()
    bpy.ops.preferences.addon_enable(module=NAME)
    bpy.context.preferences.use_preferences_save = True
    bpy.ops.wm.save_userpref()
    return target


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    where = install(link="--link" in args)
    print(f"lumitrace add-on {'linked' if '--link' in args else 'installed'} at {where} "
          "and enabled")
