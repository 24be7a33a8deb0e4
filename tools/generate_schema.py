"""Regenerate the lumitrace codeless USD schema from ``schemas/schema.usda``.

Usage (from anywhere; needs ``jinja2``, which the runtime does not)::

    pip install jinja2
    python tools/generate_schema.py            # rewrite schemas/plugInfo.json, generatedSchema.usda
    python tools/generate_schema.py --check    # exit 1 if the committed files are stale

It runs usd-core's generator (``python -m pxr.Usd.usdGenSchema schema.usda DIR``) in a
temporary folder, replaces the ``@PLUG_INFO_*@`` placeholders of ``plugInfo.json``
(``LibraryPath`` "", ``ResourcePath`` ".", ``Root`` "."), so the plugin registers from
its own folder, and copies both files into ``schemas/``.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas"
OUTPUTS = ("plugInfo.json", "generatedSchema.usda")
PLACEHOLDERS = {
    "@PLUG_INFO_LIBRARY_PATH@": "",
    "@PLUG_INFO_RESOURCE_PATH@": ".",
    "@PLUG_INFO_ROOT@": ".",
}


def generate(out_dir: Path) -> None:
    """Run the generator on ``schemas/schema.usda`` into ``out_dir`` and fix plugInfo."""
    # The generator resolves the sublayered @usd/schema.usda@ through the plugin system and
    # reads schema.usda relative to the working directory: run it from a copy.
    shutil.copy2(SCHEMAS / "schema.usda", out_dir / "schema.usda")
    # Its notes about C++ build files (__init__.py, CMakeLists.txt, module.cpp) do not apply
    # to a codeless schema: show its output only when it fails.
    result = subprocess.run([sys.executable, "-m", "pxr.Usd.usdGenSchema", "-q", "schema.usda",
                             "."], cwd=out_dir, capture_output=True, text=True)
    if result.returncode != 0:
        sys.stderr.write(result.stdout + result.stderr)
        raise SystemExit(f"usdGenSchema failed with exit status {result.returncode}")
    plug_info = out_dir / "plugInfo.json"
    text = plug_info.read_text(encoding="utf-8")
    for placeholder, value in PLACEHOLDERS.items():
        text = text.replace(placeholder, value)
    plug_info.write_text(text, encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="compare with the committed files instead of writing them")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp_dir = Path(tmp)
        generate(tmp_dir)
        stale = [name for name in OUTPUTS
                 if not (SCHEMAS / name).exists()
                 or (SCHEMAS / name).read_bytes() != (tmp_dir / name).read_bytes()]
        if args.check:
            for name in stale:
                print(f"schemas/{name} is stale: run python tools/generate_schema.py")
            return 1 if stale else 0
        for name in OUTPUTS:
            shutil.copyfile(tmp_dir / name, SCHEMAS / name)
            print(f"wrote schemas/{name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
