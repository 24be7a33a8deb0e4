"""A stand-in for Blender's UILayout that records what a panel draws (panels draw only in
a window, which Blender as a module has not)."""
from types import SimpleNamespace


class Layout:
    def __init__(self, lines=None):
        self.lines = [] if lines is None else lines

    def _sub(self, *args, **kwargs):
        return Layout(self.lines)

    row = column = box = _sub

    def label(self, text="", **kwargs):
        self.lines.append(("label", text))

    def prop(self, data, path, text="", **kwargs):
        self.lines.append(("prop", path, text, data[path[2:-2]] if path.startswith('["')
                           else getattr(data, path)))

    def operator(self, idname, text="", **kwargs):
        self.lines.append(("operator", idname))
        return SimpleNamespace()


def draw(panel, **context):
    """Draw ``panel`` (a registered Panel class) in ``context``; the lines it drew."""
    layout = Layout()
    panel.draw(SimpleNamespace(layout=layout), SimpleNamespace(**context))
    return layout.lines
