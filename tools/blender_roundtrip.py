"""What Blender does to lumitrace stages: each stage imported and exported by plain Blender
(its own USD importer and exporter, custom properties on) and by the lumitrace add-on,
compared with the original, and each export traced by lumitrace beside the original.

Run it in the Blender environment (``sh tools/setup.sh --blender`` makes ``.venv-blender``)::

    .venv-blender/bin/python tools/blender_roundtrip.py [STAGE ...] [--photons N]
        [--seed S] [--out DIR] [--lumitrace CMD] [--json FILE]

Default stages: every ``.usda`` of ``stages/`` and ``stages/reference/``. Tracing runs
``lumitrace trace`` of the project's environment (``.venv/bin/lumitrace``, or ``CMD``).

Prints two Markdown tables. *What survived*: per stage and path (plain Blender, the add-on)
how many of the original's parts are at their prim paths, how many are placed where they
were (world bounds in metres, to 1e-6 of their size), how many keep their lumitrace
optical values, how many lights keep their flux and shaping inputs, how much of the
stage's metadata (defaultPrim, metersPerUnit, upAxis, customLayerData) is kept, and
whether the original's layers are still composed (sublayered) or flattened. *Traced*:
flux, light output ratio and peak intensity with their standard errors, the original's and
each export's at the same seed; "same counts" where an export's map equals the
original's count for count.
"""
from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile

import bpy

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "service"))
import lumitrace_blender  # noqa: E402
from lumitrace_blender import exporter, records  # noqa: E402
from lumitrace_blender.usd import pxr_modules  # noqa: E402

Usd, Sdf, UsdGeom, UsdLux, UsdShade, Gf, Vt = pxr_modules()
LIGHTS = ("RectLight", "DiskLight", "SphereLight", "CylinderLight")


def default_stages() -> list[str]:
    out = []
    for folder in ("stages", os.path.join("stages", "reference")):
        path = os.path.join(ROOT, folder)
        out += sorted(os.path.join(path, f) for f in os.listdir(path) if f.endswith(".usda"))
    return out


# -- the two round trips ------------------------------------------------------------------

def plain_blender(stage: str, out: str) -> str:
    """Blender's own USD import and export (custom properties exported)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=stage)
    bpy.ops.wm.usd_export(filepath=out, export_custom_properties=True)
    return out


def with_addon(stage: str, out: str) -> str:
    """The add-on's import and export (a stage over the original, nothing changed)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types, "LUMITRACE_OT_import_stage"):
        lumitrace_blender.register()
    bpy.ops.lumitrace.import_stage(filepath=stage)
    exporter.export_stage(records.stage_entry(bpy.context.scene), out)
    return out


# -- comparing a stage with its export -----------------------------------------------------

def _items(stage, root_path: str | None = None):
    """Gprims and lights (below ``root_path``): prim -> kind."""
    root = stage.GetPrimAtPath(root_path) if root_path else stage.GetPseudoRoot()
    for prim in Usd.PrimRange(root):
        if prim.IsA(UsdGeom.Gprim):
            yield prim, "part"
        elif prim.GetTypeName() in LIGHTS:
            yield prim, "light"


def _match(prim, export, by_name) -> tuple[object, bool]:
    """The export's prim for ``prim``: at its path, else one of its name and type."""
    same = export.GetPrimAtPath(prim.GetPath())
    if same and same.GetTypeName() == prim.GetTypeName():
        return same, True
    for other in by_name.get((prim.GetName(), prim.GetTypeName()), []):
        return other, False
    return None, False


def _bounds_m(prim, stage):
    """World bounds in metres of a gprim, or world position of a light."""
    mpu = UsdGeom.GetStageMetersPerUnit(stage)
    if prim.IsA(UsdGeom.Gprim):
        cache = UsdGeom.BBoxCache(Usd.TimeCode.Default(), ["default", "render"])
        r = cache.ComputeWorldBound(prim).ComputeAlignedRange()
        return [v * mpu for v in (*r.GetMin(), *r.GetMax())]
    m = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    return [v * mpu for v in m.ExtractTranslation()] * 2


def _same_bounds(a, b) -> bool:
    size = max(1e-9, max(abs(x) for x in a))
    return all(abs(x - y) <= 1e-6 * size for x, y in zip(a, b))


def _optical(prim) -> dict:
    """The lumitrace values the prim is traced with: its bound material's, then its own."""
    values = {}
    api = UsdShade.MaterialBindingAPI(prim)
    for purpose in (UsdShade.Tokens.full, UsdShade.Tokens.allPurpose):
        found = api.ComputeBoundMaterial(purpose)
        material = found[0] if isinstance(found, tuple) else found
        if material:
            values.update(_lumitrace(material.GetPrim()))
            break
    values.update(_lumitrace(prim))
    return values


def _lumitrace(prim) -> dict:
    out = {}
    for attr in prim.GetAttributes():
        name = attr.GetName()
        if name.startswith("lumitrace:") and not name.startswith("lumitrace:result:") \
                and attr.HasAuthoredValue():
            value = attr.Get()
            out[name] = str(value) if hasattr(value, "__len__") else value
    return out


def _shaping(prim) -> dict:
    return {a.GetName(): str(a.Get()) for a in prim.GetAttributes()
            if a.GetName().startswith("inputs:shaping:") and a.HasAuthoredValue()}


def _metadata(stage) -> dict:
    root = stage.GetRootLayer()
    layers = [root] + [Sdf.Layer.FindOrOpen(root.ComputeAbsolutePath(p))
                       for p in root.subLayerPaths]
    data = {}
    for layer in reversed([lay for lay in layers if lay is not None]):
        data.update(layer.customLayerData)
    default = stage.GetDefaultPrim()
    return {"defaultPrim": default.GetName() if default else "",
            "metersPerUnit": UsdGeom.GetStageMetersPerUnit(stage),
            "upAxis": str(UsdGeom.GetStageUpAxis(stage)),
            "customLayerData": json.dumps(data, sort_keys=True, default=str)}


def survived(original_path: str, export_path: str) -> dict:
    """What of the original the export keeps: counts, each with its total (``*_of``)."""
    original = Usd.Stage.Open(original_path)
    export = Usd.Stage.Open(export_path)
    luminaire = original.GetDefaultPrim().GetPath().pathString
    by_name: dict = {}
    for prim, _ in _items(export):
        by_name.setdefault((prim.GetName(), prim.GetTypeName()), []).append(prim)
    c = dict.fromkeys(("items", "at_path", "placed", "optical", "optical_of", "lights_of",
                       "flux", "shaping", "shaping_of"), 0)
    for prim, kind in _items(original, luminaire):
        c["items"] += 1
        c["lights_of"] += kind == "light"
        mine = _optical(prim) if kind == "part" else _shaping(prim)
        c["optical_of" if kind == "part" else "shaping_of"] += bool(mine)
        other, at_path = _match(prim, export, by_name)
        if other is None:
            continue
        c["at_path"] += at_path
        c["placed"] += _same_bounds(_bounds_m(prim, original), _bounds_m(other, export))
        if kind == "part":
            c["optical"] += bool(mine) and _optical(other) == mine
        else:
            c["shaping"] += bool(mine) and _shaping(other) == mine
            flux = prim.GetAttribute("lumitrace:luminousFlux")
            theirs = other.GetAttribute("lumitrace:luminousFlux")
            c["flux"] += bool(flux and flux.HasAuthoredValue() and theirs
                              and theirs.HasAuthoredValue() and flux.Get() == theirs.Get())
    meta_a, meta_b = _metadata(original), _metadata(export)
    c["metadata"] = sum(meta_a[k] == meta_b[k] for k in meta_a)
    c["metadata_of"] = len(meta_a)
    root = export.GetRootLayer()
    c["composed"] = any(os.path.realpath(root.ComputeAbsolutePath(p)) ==
                        os.path.realpath(original_path) for p in root.subLayerPaths)
    return c


# -- tracing ---------------------------------------------------------------------------------

def trace(command: list[str], stage: str, out: str, photons: int, seed: int) -> dict:
    """``lumitrace trace --json`` of ``stage`` (its summary, or its refusal)."""
    p = subprocess.run([*command, "trace", stage, "--photons", str(photons), "--seed",
                        str(seed), "--resolution", "32", "--no-pictures", "--no-sublayer",
                        "--no-progress", "--json", "--out", out],
                       capture_output=True, text=True, timeout=900)
    if p.returncode != 0:
        lines = [line for line in p.stderr.strip().splitlines() if line.strip()]
        return {"refused": lines[-1] if lines else f"exit {p.returncode}"}
    summary = json.loads(p.stdout.strip().splitlines()[-1])
    ph = summary["photometry"]
    from_exr = summary["outputs"]["intensity_map"]
    return {"flux": ph["luminous_flux"], "flux_error": ph["luminous_flux_error"],
            "lor": summary["light_output_ratio"],
            "lor_error": summary["light_output_ratio_error"],
            "peak": ph["peak_intensity"], "peak_error": ph["peak_intensity_error"],
            "scene_hash": summary["scene_hash"], "map": from_exr,
            "counts": _counts_digest(from_exr)}


def _counts_digest(exr: str) -> str:
    """SHA-256 of the map's photon counts (its ``count`` channel, read with the
    OpenImageIO that Blender ships): equal digests are equal maps, count for count."""
    import hashlib

    import OpenImageIO as oiio  # beside pxr in Blender's Python
    image = oiio.ImageInput.open(exr)
    try:
        k = list(image.spec().channelnames).index("count")
        return hashlib.sha256(image.read_image(0, 0, k, k + 1, "float").tobytes()).hexdigest()
    finally:
        image.close()


def lumitrace_command(given: str | None) -> list[str]:
    if given:
        return shlex.split(given)
    local = os.path.join(ROOT, ".venv", "bin", "lumitrace")
    return [local] if os.path.exists(local) else ["lumitrace"]


# -- the tables ---------------------------------------------------------------------------

def _k(n, of) -> str:
    return f"{n}/{of}" if of else "-"


def survival_table(rows: list[dict]) -> str:
    head = ("| stage | round trip | parts and lights at their paths | placed as before | "
            "optical values | lights' flux | shaping | metadata | composition |")
    lines = [head, "|" + " --- |" * 9]
    for r in rows:
        s = r["survived"]
        lines.append(
            f"| {r['stage']} | {r['path']} | {_k(s['at_path'], s['items'])} | "
            f"{_k(s['placed'], s['items'])} | {_k(s['optical'], s['optical_of'])} | "
            f"{_k(s['flux'], s['lights_of'])} | {_k(s['shaping'], s['shaping_of'])} | "
            f"{_k(s['metadata'], s['metadata_of'])} | "
            f"{'sublayers the original' if s['composed'] else 'flattened'} |")
    return "\n".join(lines)


def _fig(t: dict, key: str, digits: int) -> str:
    if "refused" in t:
        return "refused"
    return f"{t[key]:.{digits}f} ± {t[key + '_error']:.{digits}f}"


def traced_table(rows: list[dict], originals: dict) -> str:
    lines = ["| stage | traced | flux (lm) | LOR | peak (cd) | map |", "|" + " --- |" * 6]
    for stage, t in originals.items():
        lines.append(f"| {stage} | original | {_fig(t, 'flux', 1)} | {_fig(t, 'lor', 4)} | "
                     f"{_fig(t, 'peak', 1)} | |")
        for r in (r for r in rows if r["stage"] == stage):
            e = r["traced"]
            if "refused" in e:
                why = e["refused"].replace("lumitrace: error: ", "").replace("|", "/")
                note = "refused: " + why
            else:
                note = "same counts" if e["counts"] == t.get("counts") else "differs"
            lines.append(f"| | {r['path']} | {_fig(e, 'flux', 1)} | {_fig(e, 'lor', 4)} | "
                         f"{_fig(e, 'peak', 1)} | {note} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("stages", nargs="*", help="stages (default: every one in stages/)")
    parser.add_argument("--photons", type=int, default=200_000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default=None, help="folder for the exports (default: "
                                                    "a temporary one)")
    parser.add_argument("--lumitrace", default=None,
                        help="command running lumitrace (default: .venv/bin/lumitrace)")
    parser.add_argument("--json", default=None, help="also write the results to this file")
    args = parser.parse_args(argv)
    stages = [os.path.abspath(s) for s in args.stages] or default_stages()
    out = args.out or tempfile.mkdtemp(prefix="blender-roundtrip-")
    command = lumitrace_command(args.lumitrace)
    rows, originals = [], {}
    for stage in stages:
        name = os.path.relpath(stage, ROOT) if stage.startswith(ROOT) else stage
        base = os.path.splitext(os.path.basename(stage))[0]
        folder = os.path.join(out, base)
        os.makedirs(folder, exist_ok=True)
        originals[name] = trace(command, stage, os.path.join(folder, "original"),
                                args.photons, args.seed)
        for path, run in (("plain Blender", plain_blender), ("add-on", with_addon)):
            tag = "plain" if run is plain_blender else "addon"
            exported = run(stage, os.path.join(folder, f"{base}.{tag}.usda"))
            rows.append({"stage": name, "path": path, "file": exported,
                         "survived": survived(stage, exported),
                         "traced": trace(command, exported, os.path.join(folder, tag),
                                         args.photons, args.seed)})
            print(f"{name}: {path} done", file=sys.stderr, flush=True)
    print("What survived\n")
    print(survival_table(rows))
    print(f"\nTraced ({args.photons:,} photons, seed {args.seed})\n")
    print(traced_table(rows, originals))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"rows": rows, "originals": originals, "photons": args.photons,
                       "seed": args.seed}, f, indent=1)
    return 0


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    sys.exit(main(argv))
