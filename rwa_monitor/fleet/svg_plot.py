"""Panels of points with error bars, lines and marks, drawn as one SVG figure.

The fleet report's plots (fleet/report.py). Written here instead of drawn with a plotting
library: a daily fleet run redraws them every day, and a library's import and raster
drawing took 2.1 s of a 9.5 s daily run of 100 spacecraft (seven plots; 0.2 h of a year
of daily runs), where this text takes milliseconds. The page gets vector plots, sharp at
any zoom, and nothing else changes: what is drawn is fleet/report.py's choice.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import html
import math
from typing import Callable, Sequence

import numpy as np

BLUE, ORANGE, RED, GREY = '#1f77b4', '#ff7f0e', '#d62728', '#999999'
FONT = 'font-family="sans-serif"'
PANEL_MARGIN = {'left': 92.0, 'right': 14.0, 'top': 40.0, 'bottom': 48.0}


@dataclass
class Panel:
    """One panel: points with ±error bars, and what is drawn over them.

    ``lines``: (x pair, y pair, colour, legend label) segments; ``levels``: horizontal
    (y, colour, label) dotted lines; ``marks``: vertical (x, colour, text) lines with their
    text along them. Non-finite values are left out.
    """

    x: np.ndarray
    y: np.ndarray
    err: np.ndarray
    x_label: str
    y_label: str
    point_label: str = ''
    lines: list[tuple[tuple[float, float], tuple[float, float], str, str]] = field(
        default_factory=list)
    levels: list[tuple[float, str, str]] = field(default_factory=list)
    marks: list[tuple[float, str, str]] = field(default_factory=list)
    mark_label: str = ''


def figure(title: str, panels: Sequence[Panel], width: int = 1170, height: int = 380
           ) -> str:
    """Return the SVG document of ``panels`` side by side under ``title`` (sizes in px)."""
    step = width / max(len(panels), 1)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" {FONT} font-size="13">',
             f'<rect width="{width}" height="{height}" fill="white"/>',
             f'<text x="{width / 2:.1f}" y="20" text-anchor="middle" font-size="16">'
             f'{_e(title)}</text>']
    for i, panel in enumerate(panels):
        parts.append(_panel(panel, i, i * step, step, height))
    parts.append('</svg>')
    return '\n'.join(parts)


def nice_ticks(low: float, high: float, count: int = 6) -> np.ndarray:
    """Return round ticks in [low, high], at most ``count + 1`` of them.

    The step is the finest of 1, 2, 2.5 or 5 times a power of ten that gives so few.
    """
    if not (math.isfinite(low) and math.isfinite(high)) or high <= low:
        return np.array([low]) if math.isfinite(low) else np.array([])
    power = 10.0 ** math.floor(math.log10((high - low) / count))
    for multiple in (1.0, 2.0, 2.5, 5.0, 10.0, 20.0, 25.0, 50.0):
        step = multiple * power
        first, last = math.ceil(low / step - 1e-9), math.floor(high / step + 1e-9)
        if last - first + 1 <= count + 1:
            break
    ticks = np.arange(first, last + 1) * step
    return np.where(np.abs(ticks) < step * 1e-9, 0.0, ticks)


def tick_texts(ticks: np.ndarray) -> tuple[list[str], int]:
    """Return tick labels and the power of ten they are given in (0: as they are).

    Values of magnitude below 0.01 or from 1e5 up are written as multiples of a common
    power of ten, which the axis label then names (``× 1e-4``); each label has the
    fewest decimals that write every tick exactly.
    """
    if not ticks.size:
        return [], 0
    top = float(np.max(np.abs(ticks)))
    power = 0 if top == 0 or 1e-2 <= top < 1e5 else math.floor(math.log10(top))
    scaled = ticks / 10.0 ** power
    tolerance = 1e-6 * max(float(np.max(np.abs(scaled))), 1e-300)
    decimals = next((d for d in range(7)
                     if np.all(np.abs(np.round(scaled, d) - scaled) <= tolerance)), 6)
    return [f'{v:.{decimals}f}' for v in scaled], power


def _panel(panel: Panel, index: int, left: float, width: float, height: float) -> str:
    m = PANEL_MARGIN
    x0, x1 = left + m['left'], left + width - m['right']
    y0, y1 = height - m['bottom'], m['top']
    ok = np.isfinite(panel.x) & np.isfinite(panel.y)
    x, y = panel.x[ok], panel.y[ok]
    err = np.where(np.isfinite(panel.err[ok]), panel.err[ok], 0.0)
    xs = [x, np.array([v for line in panel.lines for v in line[0]]),
          np.array([v for v, _, _ in panel.marks])]
    ys = [y - err, y + err, np.array([v for line in panel.lines for v in line[1]]),
          np.array([v for v, _, _ in panel.levels])]
    (xa, xb), (ya, yb) = _span(xs, 0.02), _span(ys, 0.06)

    def sx(v: np.ndarray | float) -> np.ndarray | float:
        return x0 + (np.asarray(v) - xa) / (xb - xa) * (x1 - x0)

    def sy(v: np.ndarray | float) -> np.ndarray | float:
        return y0 - (np.asarray(v) - ya) / (yb - ya) * (y0 - y1)

    clip = f'clip{index}'
    out = [f'<clipPath id="{clip}"><rect x="{x0:.1f}" y="{y1:.1f}" width="{x1 - x0:.1f}" '
           f'height="{y0 - y1:.1f}"/></clipPath>']
    out += _axes(panel, (x0, x1, y0, y1), (xa, xb, ya, yb), sx, sy)
    body = [f'<g clip-path="url(#{clip})">']
    if x.size:
        px, lo, hi = sx(x), sy(y - err), sy(y + err)
        bars = ''.join(f'M{a:.1f} {b:.1f}V{c:.1f}' for a, b, c in zip(px, lo, hi))
        dots = ''.join(f'M{a:.1f} {b:.1f}h0' for a, b in zip(px, sy(y)))
        body += [f'<path d="{bars}" stroke="{GREY}" stroke-width="1" fill="none"/>',
                 f'<path d="{dots}" stroke="{BLUE}" stroke-width="5" '
                 'stroke-linecap="round" fill="none"/>']
    for (xp, yp), colour in ((line[0:2], line[2]) for line in panel.lines):
        if all(math.isfinite(v) for v in (*xp, *yp)):
            body.append(f'<line x1="{sx(xp[0]):.1f}" y1="{sy(yp[0]):.1f}" '
                        f'x2="{sx(xp[1]):.1f}" y2="{sy(yp[1]):.1f}" stroke="{colour}" '
                        'stroke-width="2"/>')
    for value, colour, _ in panel.levels:
        if math.isfinite(value):
            body.append(f'<line x1="{x0:.1f}" x2="{x1:.1f}" y1="{sy(value):.1f}" '
                        f'y2="{sy(value):.1f}" stroke="{colour}" stroke-width="1.5" '
                        'stroke-dasharray="2 3"/>')
    for value, colour, text in panel.marks:
        if math.isfinite(value):
            at = sx(value)
            body.append(f'<line x1="{at:.1f}" x2="{at:.1f}" y1="{y0:.1f}" y2="{y1:.1f}" '
                        f'stroke="{colour}" stroke-width="1.2"/>')
            body.append(f'<text transform="translate({at - 3:.1f} {y1 + 4:.1f}) rotate(-90)"'
                        f' text-anchor="end" font-size="12" fill="{colour}">{_e(text)}</text>')
    body.append('</g>')
    out += body + _legend(panel, x0, y0)
    return '\n'.join(out)


def _span(groups: Sequence[np.ndarray], pad: float) -> tuple[float, float]:
    values = np.concatenate([np.asarray(g, dtype=float).ravel() for g in groups])
    values = values[np.isfinite(values)]
    if not values.size:
        return 0.0, 1.0
    low, high = float(values.min()), float(values.max())
    if high <= low:
        half = abs(low) * 0.05 or 1.0
        return low - half, high + half
    return low - pad * (high - low), high + pad * (high - low)


def _axes(panel: Panel, box: tuple[float, float, float, float],
          limits: tuple[float, float, float, float], sx: Callable, sy: Callable) -> list[str]:
    x0, x1, y0, y1 = box
    xa, xb, ya, yb = limits
    out = [f'<rect x="{x0:.1f}" y="{y1:.1f}" width="{x1 - x0:.1f}" height="{y0 - y1:.1f}" '
           'fill="none" stroke="#444"/>']
    x_at, x_power = _placed_ticks(xa, xb, sx)
    for at, text in x_at:
        out.append(f'<line x1="{at:.1f}" x2="{at:.1f}" y1="{y0:.1f}" y2="{y0 + 5:.1f}" '
                   'stroke="#444"/>')
        out.append(f'<text x="{at:.1f}" y="{y0 + 19:.1f}" text-anchor="middle">{text}</text>')
    y_at, y_power = _placed_ticks(ya, yb, sy)
    for at, text in y_at:
        out.append(f'<line x1="{x0 - 5:.1f}" x2="{x0:.1f}" y1="{at:.1f}" y2="{at:.1f}" '
                   'stroke="#444"/>')
        out.append(f'<line x1="{x0:.1f}" x2="{x1:.1f}" y1="{at:.1f}" y2="{at:.1f}" '
                   'stroke="#eeeeee"/>')
        out.append(f'<text x="{x0 - 8:.1f}" y="{at + 4:.1f}" text-anchor="end">{text}</text>')
    x_label = panel.x_label + (f' (× 1e{x_power})' if x_power else '')
    y_label = panel.y_label + (f' (× 1e{y_power})' if y_power else '')
    out.append(f'<text x="{(x0 + x1) / 2:.1f}" y="{y0 + 40:.1f}" text-anchor="middle">'
               f'{_e(x_label)}</text>')
    out.append(f'<text transform="translate({x0 - 76:.1f} {(y0 + y1) / 2:.1f}) rotate(-90)" '
               f'text-anchor="middle">{_e(y_label)}</text>')
    return out


def _placed_ticks(low: float, high: float, scale: Callable[[float], float]
                  ) -> tuple[list[tuple[float, str]], int]:
    """Return each round tick's position on the page and text, and their power of ten."""
    ticks = nice_ticks(low, high)
    texts, power = tick_texts(ticks)
    return [(float(scale(v)), text) for v, text in zip(ticks, texts)], power


def _legend(panel: Panel, x0: float, y0: float) -> list[str]:
    entries = []
    if panel.point_label and panel.x.size:
        entries.append(('dot', BLUE, panel.point_label))
    entries += [('line', line[2], line[3]) for line in panel.lines if line[3]]
    entries += [('dash', colour, label) for _, colour, label in panel.levels if label]
    if panel.marks and panel.mark_label:
        entries.append(('line', panel.marks[0][1], panel.mark_label))
    if not entries:
        return []
    row, wide = 17.0, 30 + 7.0 * max(len(text) for _, _, text in entries)
    top = y0 - 8 - row * len(entries)
    out = [f'<rect x="{x0 + 8:.1f}" y="{top - 4:.1f}" width="{wide:.1f}" '
           f'height="{row * len(entries) + 4:.1f}" fill="white" fill-opacity="0.85" '
           'stroke="#cccccc"/>']
    for i, (shape, colour, text) in enumerate(entries):
        mid = top + row * i + row / 2
        if shape == 'dot':
            out.append(f'<path d="M{x0 + 22:.1f} {mid - 6:.1f}V{mid + 6:.1f}" '
                       f'stroke="{GREY}"/><circle cx="{x0 + 22:.1f}" cy="{mid:.1f}" r="2.5" '
                       f'fill="{colour}"/>')
        else:
            dash = ' stroke-dasharray="2 3"' if shape == 'dash' else ''
            out.append(f'<line x1="{x0 + 13:.1f}" x2="{x0 + 31:.1f}" y1="{mid:.1f}" '
                       f'y2="{mid:.1f}" stroke="{colour}" stroke-width="2"{dash}/>')
        out.append(f'<text x="{x0 + 36:.1f}" y="{mid + 4:.1f}" font-size="12">'
                   f'{_e(text)}</text>')
    return out


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)
