"""The datasheet of a result: one self-contained HTML page (pictures inlined as PNG) and a
PDF of one or two A4 pages, both rendered from the same sections of the result record
(:mod:`.datasheet_content`), so the page shows the numbers the photometric files hold.

Pictures: the luminaire inside its photometric solid (the published picture, where drawn),
the polar curve with its error band, beam and field angles and peak, and, for a narrow
beam, the Cartesian diagram (:mod:`lumitrace.photometry.curves`).
"""
from __future__ import annotations

import base64
import io
import json
from dataclasses import dataclass
from datetime import datetime, timezone
from html import escape
from typing import Mapping

from ..photometry.grid import CGammaGrid
from .datasheet_content import Section, luminaire_name, sections


@dataclass(frozen=True)
class DatasheetInput:
    """What a datasheet is made of: the result ``record``, the published ``grid`` (cd,
    with sigma), the luminaire's ``info`` (:class:`~lumitrace.scene.LuminaireInfo`), the
    photometric solid's PNG (or None), the run id and the colour diagram's PNG."""

    record: Mapping
    grid: CGammaGrid
    info: object
    solid_png: bytes | None = None
    run_id: str = ""
    #: the colour over angle diagram's PNG (a stage with colour, pictures drawn), or None
    colour_png: bytes | None = None

    @property
    def name(self) -> str:
        return luminaire_name(self.record, self.info)


def curve_pngs(data: DatasheetInput, dpi: int = 110, polar: bool = True
               ) -> dict[str, bytes]:
    """The polar curve (unless ``polar`` is False) and, for a narrow beam, the Cartesian
    diagram as PNG bytes."""
    from ..pyplot import pyplot

    plt = pyplot()

    from ..photometry.curves import draw_cartesian, draw_polar, is_narrow

    lamp = float(data.record.get("lamp_flux") or 0.0)
    out = {}
    if polar:
        fig = plt.figure(figsize=(4.6, 4.9), dpi=dpi)
        draw_polar(fig.add_subplot(projection="polar"), data.grid, lamp, data.record,
                   data.name)
        fig.tight_layout()
        out["polar"] = _png(fig)
    if is_narrow(data.record):
        fig, ax = plt.subplots(figsize=(4.6, 3.4), dpi=dpi)
        draw_cartesian(ax, data.grid, lamp, data.record, data.name)
        fig.tight_layout()
        out["cartesian"] = _png(fig)
    return out


def _png(fig) -> bytes:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


def _img(png: bytes, alt: str) -> str:
    return (f'<img alt="{escape(alt)}" src="data:image/png;base64,'
            f'{base64.b64encode(png).decode()}">')


def _table(s: Section) -> str:
    head = "" if not any(s.header) else \
        "<tr>" + "".join(f"<th>{escape(h)}</th>" for h in s.header) + "</tr>"
    rows = []
    for row in s.rows:
        cells = []
        for c in row:
            attrs = "" if c.key is None else \
                f' data-key="{escape(c.key)}" data-value="{escape(json.dumps(c.value))}"'
            cells.append(f"<td{attrs}>{escape(c.text)}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    note = f'<p class="note">{escape(s.note)}</p>' if s.note else ""
    return (f'<section><h2>{escape(s.title)}</h2><table>{head}{"".join(rows)}</table>'
            f"{note}</section>")


_STYLE = """
body { font: 12px/1.35 Helvetica, Arial, sans-serif; margin: 16px auto; max-width: 1000px;
       color: #222; }
h1 { font-size: 20px; margin: 0; } h2 { font-size: 14px; margin: 14px 0 4px; }
.sub { color: #555; margin: 2px 0 10px; }
.pictures { display: flex; flex-wrap: wrap; gap: 8px; align-items: flex-start; }
.pictures img { max-width: 320px; border: 1px solid #ddd; }
.grid { display: grid; grid-template-columns: 1fr 1fr; gap: 0 24px; }
table { border-collapse: collapse; width: 100%; }
td, th { border-bottom: 1px solid #e3e3e3; padding: 2px 6px; text-align: left;
         vertical-align: top; }
td[data-key] { font-variant-numeric: tabular-nums; }
.grid td:first-child { width: 44%; }
.note { color: #555; font-size: 11px; margin: 2px 0; }
"""


def datasheet_html(data: DatasheetInput, curves: Mapping[str, bytes] | None = None,
                   when: datetime | None = None) -> str:
    """The datasheet as one HTML page (``curves``: the PNGs of :func:`curve_pngs`; drawn
    here when not given). The record itself is embedded as JSON (``#lumitrace-record``)."""
    curves = curve_pngs(data) if curves is None else curves
    when = when or datetime.now(timezone.utc)
    info = data.info
    left, right, wide = sections(data.record, info)
    pics = []
    if data.solid_png:
        pics.append(_img(data.solid_png, "the luminaire in its photometric solid"))
    pics += [_img(png, f"{kind} diagram") for kind, png in curves.items()]
    colour = "" if not data.colour_png else \
        f'<section><h2>Colour over angle</h2>{_img(data.colour_png, "colour over angle")}' \
        "</section>"
    sub = " · ".join(x for x in (info.manufacturer, info.catalogue_number) if x)
    # "</" never closes the script element early; JSON reads "<\\/" as "</"
    record_json = json.dumps(dict(data.record), default=str).replace("</", "<\\/")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{escape(data.name)}: datasheet</title><style>{_STYLE}</style></head>"
            f"<body><h1>{escape(data.name)}</h1>"
            f'<p class="sub">{escape(sub)}{" · " if sub else ""}photometric datasheet, '
            f"{when:%Y-%m-%d}{', run ' + escape(data.run_id) if data.run_id else ''}</p>"
            f'<div class="pictures">{"".join(pics)}</div>'
            f'<div class="grid"><div>{"".join(_table(s) for s in left)}</div>'
            f'<div>{"".join(_table(s) for s in right)}</div></div>'
            f'{"".join(_table(s) for s in wide)}{colour}'
            '<script type="application/json" id="lumitrace-record">'
            f"{record_json}</script></body></html>\n")
