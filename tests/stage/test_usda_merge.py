"""The text merge's check that an edited ``.usda`` file reads back as USD's own merge: it
compares every field by value, list ops (API schemas, relationship targets) included,
which have no ``repr`` of their own (only their address)."""
from __future__ import annotations

from pxr import Sdf

from lumitrace.delta.usda_merge import _differences, merge_text

BASE = '''#usda 1.0
(
    defaultPrim = "Luminaire"
)

# a comment that stays
def Xform "Luminaire"
{
    def Mesh "Reflector" (
        prepend apiSchemas = ["MaterialBindingAPI"]
    )
    {
        rel material:binding = </Luminaire/Materials/Aluminium>
        float lumitrace:roughness = 0.1  # measured
    }
}
'''


def _layer(text: str) -> Sdf.Layer:
    layer = Sdf.Layer.CreateAnonymous(".usda")
    assert layer.ImportFromString(text)
    return layer


def test_list_ops_are_compared_by_their_items():
    """Two files that differ only in an API schema or a relationship target differ; the
    same file read twice does not (whatever addresses its list ops get)."""
    same = _layer(BASE)
    assert _differences(BASE, same) == ""
    other_schema = _layer(BASE.replace('["MaterialBindingAPI"]', '["CollectionAPI"]'))
    assert "/Luminaire/Reflector" in _differences(BASE, other_schema)
    other_target = _layer(BASE.replace("Materials/Aluminium", "Materials/Paint"))
    assert "/Luminaire/Reflector.material:binding" in _differences(BASE, other_target)


def test_an_edit_of_a_prim_with_api_schemas_is_made_as_text():
    """An edit of a property on a prim that carries API schemas and a binding is a text
    edit: the comments stay, the value changes, and the file reads back as the merge."""
    edits = _layer('#usda 1.0\nover "Luminaire"\n{\n    over "Reflector"\n    {\n'
                   '        float lumitrace:roughness = 0.3\n    }\n}\n')
    merged = _layer(BASE.replace("= 0.1  # measured", "= 0.3"))
    text, why = merge_text(BASE, edits, merged)
    assert why == "" and text is not None
    assert "# a comment that stays" in text and "= 0.3  # measured" in text
    assert _differences(text, merged) == ""
