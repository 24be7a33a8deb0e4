"""The datasheet as a PDF (matplotlib's PdfPages): A4 portrait, the pictures and the main
figures on page one, the tables after them, from the same sections as the HTML page."""
from __future__ import annotations

import contextlib
import io
import logging
from datetime import datetime, timezone

from .datasheet import DatasheetInput
from .datasheet_content import Section, sections

#: A4 portrait (inches), margins and line height (figure fractions).
PAGE = (8.27, 11.69)
LEFT, RIGHT, TOP, BOTTOM = 0.06, 0.94, 0.95, 0.05
LINE = 0.0128
#: matplotlib's line pitch in the standard Helvetica, per point of font size and unit of
#: line spacing (measured on a rendered page): what makes a column's lines LINE apart.
HELVETICA_PITCH = 0.926


#: Settings of the PDF's text: the standard Helvetica (Latin-1 glyphs).
CORE_FONTS = {"pdf.use14corefonts": True, "font.family": "sans-serif",
              "font.sans-serif": ["Helvetica"], "axes.unicode_minus": False}


@contextlib.contextmanager
def _quiet_font_lookup():
    """Silence matplotlib's note that the core Helvetica has no 'normal' weight (it uses
    its medium one, which is the same)."""
    log = logging.getLogger("matplotlib.font_manager")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def _columns(s: Section, x0: float, x1: float) -> list[float]:
    """Left edges of a section's columns between ``x0`` and ``x1``: a wide first column
    for two-column tables, even columns otherwise."""
    n = max(len(s.header), max((len(r) for r in s.rows), default=1))
    if n == 2:
        return [x0, x0 + 0.45 * (x1 - x0)]
    first = 0.16 * (x1 - x0)
    step = (x1 - x0 - first) / max(n - 1, 1)
    return [x0] + [x0 + first + k * step for k in range(n - 1)]


def _draw_section(fig, s: Section, y: float, x0: float, x1: float, size: float = 7.0
                  ) -> float:
    """Draw a section from height ``y`` down; returns the height below it."""
    fig.text(x0, y, s.title, fontsize=size + 2.5, weight="bold", va="top", parse_math=False)
    y -= 1.5 * LINE
    cols = _columns(s, x0, x1)
    if any(s.header):
        for x, h in zip(cols, s.header):
            fig.text(x, y - 0.8 * LINE, h, fontsize=size, weight="bold", va="baseline")
        y -= LINE
    if s.rows:
        # one text per column (a text is the slow part of a PDF page): lines LINE apart
        spacing = LINE * PAGE[1] * 72.0 / size / HELVETICA_PITCH
        for k, x in enumerate(cols):
            column = "\n".join(row[k].text if k < len(row) else "" for row in s.rows)
            # baselines, not tops, line up (a column's first glyphs do not shift it): a
            # text's baseline is its last line's
            fig.text(x, y - (0.8 + len(s.rows) - 1) * LINE, column, fontsize=size,
                     va="baseline", linespacing=spacing, parse_math=False)
        y -= LINE * (len(s.rows) + 0.4)
    if s.note:
        fig.text(x0, y, s.note, fontsize=size - 1, color="#555555", va="top", wrap=True,
                 parse_math=False)
        y -= LINE * (1 + len(s.note) // 150)
    return y - 0.6 * LINE


def _height(s: Section) -> float:
    return LINE * (2.1 + len(s.rows) + bool(any(s.header)) + (1 + len(s.note) // 150
                                                               if s.note else 0))


def datasheet_pdf(data: DatasheetInput, when: datetime | None = None) -> bytes:
    """The datasheet PDF (bytes): one or two A4 pages."""
    from ..pyplot import pyplot

    plt = pyplot()
    import matplotlib
    from matplotlib.backends.backend_pdf import PdfPages

    from ..photometry.curves import draw_cartesian, draw_polar, is_narrow

    when = when or datetime.now(timezone.utc)
    left, right, wide = sections(data.record, data.info)
    lamp = float(data.record.get("lamp_flux") or 0.0)
    buf = io.BytesIO()
    # the PDF's standard Helvetica, not embedded: text is most of a datasheet, and an
    # embedded font's glyphs make the page three times slower
    meta = {"Title": f"{data.name}: datasheet", "Creator": "lumitrace", "CreationDate": when}
    with matplotlib.rc_context(CORE_FONTS), _quiet_font_lookup(), \
            PdfPages(buf, metadata=meta) as pdf:
        fig = plt.figure(figsize=PAGE)
        # the luminaire's text is text: a "$" in a name starts no mathtext
        fig.text(LEFT, 0.975, data.name, fontsize=15, weight="bold", va="top",
                 parse_math=False)
        sub = " · ".join(x for x in (data.info.manufacturer, data.info.catalogue_number) if x)
        fig.text(LEFT, 0.952, f"{sub}{' · ' if sub else ''}photometric datasheet, "
                 f"{when:%Y-%m-%d}{', run ' + data.run_id if data.run_id else ''}",
                 fontsize=8, color="#555555", va="top", parse_math=False)
        narrow = is_narrow(data.record)
        if data.solid_png:
            ax = fig.add_axes((0.02, 0.60, 0.40, 0.34))
            ax.imshow(plt.imread(io.BytesIO(data.solid_png), format="png"))
            ax.set_axis_off()
        shift = 0.0 if data.solid_png else -0.30  # no picture: the curves move left
        box = (0.44 + shift, 0.635, 0.26, 0.25) if narrow else \
            (0.50 + 1.5 * shift, 0.625, 0.40, 0.27)
        polar = fig.add_axes(box, projection="polar")
        draw_polar(polar, data.grid, lamp, data.record)
        polar.title.set_fontsize(6)
        if narrow:
            ax = fig.add_axes((0.75 + 0.5 * shift, 0.67, 0.20 - 0.5 * shift, 0.21))
            draw_cartesian(ax, data.grid, lamp, data.record)
            ax.set_title("Cartesian diagram (cd/klm)", fontsize=6)
            ax.set_xlabel("deg from nadir: C180/C270 left, C0/C90 right", fontsize=5)
            ax.set_ylabel("")
        y = 0.57
        for s in left:
            y = _draw_section(fig, s, y, LEFT, 0.52)
        y = 0.57
        for s in right:
            y = _draw_section(fig, s, y, 0.56, RIGHT)
        pdf.savefig(fig)
        plt.close(fig)
        queue = list(wide)
        while queue:
            fig = plt.figure(figsize=PAGE)
            fig.text(LEFT, 0.975, f"{data.name} (continued)", fontsize=11, weight="bold",
                     va="top", parse_math=False)
            y = TOP
            while queue and (y == TOP or y - _height(queue[0]) > BOTTOM):
                y = _draw_section(fig, queue.pop(0), y, LEFT, RIGHT)
            if not queue and data.colour_png and y - 0.25 > BOTTOM:  # below the tables
                ax = fig.add_axes((LEFT, y - 0.26, RIGHT - LEFT, 0.25))
                ax.imshow(plt.imread(io.BytesIO(data.colour_png), format="png"))
                ax.set_axis_off()
            pdf.savefig(fig)
            plt.close(fig)
    return buf.getvalue()
