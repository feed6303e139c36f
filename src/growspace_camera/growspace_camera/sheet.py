"""A printable marker sheet: the layout's markers at their true size, as SVG in millimetres.

SVG in mm prints at its real size from any browser or viewer ("actual size" / 100 %), needs no
library and stays sharp. Each marker has a white quiet zone, an arrow for the edge that goes up,
its id, its side and where its centre goes in the chamber frame; a 100 mm bar on every page
checks the printer's scale.
"""

from __future__ import annotations

from pathlib import Path

from growspace_camera.markers import MarkerLayout

PAGE_MM = (210.0, 297.0)  # A4 portrait
MARGIN_MM = 12.0
CAPTION_MM = 16.0  # room under each marker for its caption
SCALE_BAR_MM = 100.0
CORNER_NAMES = ('bottom-left', 'bottom-right', 'top-right', 'top-left')


def _where(layout: MarkerLayout, index: int) -> str:
    """A word for where a marker sits relative to the others (for people placing it)."""
    x, z = layout.centres[index]
    xs = sorted(c[0] for c in layout.centres)
    zs = sorted(c[1] for c in layout.centres)
    return f'{"top" if z >= zs[2] else "bottom"}-{"right" if x >= xs[2] else "left"}'


def sheet_pages(layout: MarkerLayout) -> list[str]:
    """The SVG text of each page of the sheet (as many A4 pages as the markers need)."""
    side = layout.side * 1000.0
    quiet = side / 6.0 * 1.5  # at least one cell of white all round
    cell_w, cell_h = side + 2 * quiet, side + 2 * quiet + CAPTION_MM
    usable_w = PAGE_MM[0] - 2 * MARGIN_MM
    usable_h = PAGE_MM[1] - 2 * MARGIN_MM - 14.0  # the scale bar's row
    if cell_w > usable_w or cell_h > usable_h:
        page = (max(PAGE_MM[0], cell_w + 2 * MARGIN_MM),
                max(PAGE_MM[1], cell_h + 2 * MARGIN_MM + 14.0))  # one large marker a page
        usable_w, usable_h = page[0] - 2 * MARGIN_MM, page[1] - 2 * MARGIN_MM - 14.0
    else:
        page = PAGE_MM
    columns = max(1, int(usable_w // cell_w))
    per_page = columns * max(1, int(usable_h // cell_h))
    pages = []
    for first in range(0, len(layout.ids), per_page):
        body = []
        for k, index in enumerate(range(first, min(first + per_page, len(layout.ids)))):
            left = MARGIN_MM + (k % columns) * cell_w + quiet
            top = MARGIN_MM + (k // columns) * cell_h + quiet
            body.append(_marker(layout, index, left, top, side))
        body.append(_scale_bar(page))
        pages.append(_svg(page, body))
    return pages


def write_sheet(layout: MarkerLayout, path: str | Path) -> list[Path]:
    """Write the sheet; several pages become ``name-1.svg``, ``name-2.svg``, ...

    Returns:
        The files written.
    """
    path = Path(path)
    pages = sheet_pages(layout)
    if len(pages) == 1:
        targets = [path]
    else:
        targets = [path.with_name(f'{path.stem}-{i + 1}{path.suffix or ".svg"}')
                   for i in range(len(pages))]
    for target, text in zip(targets, pages):
        target.write_text(text, encoding='utf-8')
    return targets


def describe(layout: MarkerLayout) -> str:
    """Where each marker goes, in words (what ``growspace-camera markers`` prints)."""
    lines = [f'{layout.dictionary} markers, {layout.side * 1000:.1f} mm side (black square, '
             f'border included), on the plant plane, upright (arrow up):']
    for index, marker_id in enumerate(layout.ids):
        x, z = layout.centres[index]
        lines.append(f'  id {marker_id}: centre at x = {x:+.3f} m, z = {z:+.3f} m '
                     f'({_where(layout, index)})')
    return '\n'.join(lines)


def _marker(layout: MarkerLayout, index: int, left: float, top: float, side: float) -> str:
    marker_id = layout.ids[index]
    cells = layout.bits(marker_id)
    n = cells.shape[0]
    unit = side / n
    rects = [f'<rect x="{left + c * unit:.4f}" y="{top + r * unit:.4f}" width="{unit:.4f}" '
             f'height="{unit:.4f}"/>' for r in range(n) for c in range(n) if cells[r, c]]
    x, z = layout.centres[index]
    mid = left + side / 2
    arrow_y = top - side / 6.0 * 1.5 + 1.0
    caption_y = top + side + side / 6.0 * 1.5 + 5.0
    return (
        f'<g fill="black" shape-rendering="crispEdges">{"".join(rects)}</g>'
        f'<path d="M{mid - 2:.3f},{arrow_y + 3:.3f} L{mid:.3f},{arrow_y:.3f} '
        f'L{mid + 2:.3f},{arrow_y + 3:.3f}" stroke="#888" fill="none" stroke-width="0.3"/>'
        f'<text x="{left:.3f}" y="{caption_y:.3f}" font-size="3.2" font-family="sans-serif">'
        f'id {marker_id} ({_where(layout, index)}) · side {side:.1f} mm</text>'
        f'<text x="{left:.3f}" y="{caption_y + 4.2:.3f}" font-size="3.2" '
        f'font-family="sans-serif">centre at x = {x:+.3f} m, z = {z:+.3f} m</text>')


def _scale_bar(page: tuple[float, float]) -> str:
    y = page[1] - MARGIN_MM - 4.0
    return (f'<rect x="{MARGIN_MM}" y="{y:.3f}" width="{SCALE_BAR_MM}" height="2" fill="black"/>'
            f'<text x="{MARGIN_MM}" y="{y - 1.5:.3f}" font-size="3.2" font-family="sans-serif">'
            f'this bar must measure {SCALE_BAR_MM:.0f} mm: print at actual size (100 %)</text>')


def _svg(page: tuple[float, float], body: list[str]) -> str:
    w, h = page
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:g}mm" height="{h:g}mm" '
            f'viewBox="0 0 {w:g} {h:g}">\n<rect width="{w:g}" height="{h:g}" fill="white"/>\n'
            + '\n'.join(body) + '\n</svg>\n')
