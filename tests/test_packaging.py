"""The wheel carries every subpackage and the schema plugin."""
import tomllib
from helpers.paths import ROOT



def test_every_subpackage_is_listed_in_pyproject():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(conf["packages"])
    found = {".".join(p.parent.relative_to(ROOT / "service").parts)
             for p in (ROOT / "service" / "lumitrace").rglob("__init__.py")}
    assert found <= listed, f"add {sorted(found - listed)} to [tool.setuptools] packages"
    assert conf["package-dir"]["lumitrace.schemas"] == "schemas"
    assert (ROOT / "schemas" / "plugInfo.json").exists()
