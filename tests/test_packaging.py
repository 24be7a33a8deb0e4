"""The wheel carries every subpackage and the schema plugin."""
import tomllib
from helpers.paths import ROOT



def test_every_subpackage_is_listed_in_pyproject():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(conf["packages"])
    # every folder of the package that holds files, a data folder too (Python imports it
    # as a namespace package, and setuptools warns of any it is not told about)
    found = {".".join(p.relative_to(ROOT / "service").parts)
             for p in [ROOT / "service" / "lumitrace",
                       *(ROOT / "service" / "lumitrace").rglob("*")]
             if p.is_dir() and p.name != "__pycache__" and "__pycache__" not in p.parts
             and any(f.is_file() for f in p.iterdir())}
    assert found <= listed, f"add {sorted(found - listed)} to [tool.setuptools] packages"
    assert conf["package-dir"]["lumitrace.schemas"] == "schemas"
    assert (ROOT / "schemas" / "plugInfo.json").exists()
