"""Figure style, fresh axes and saving: what every figure of :mod:`tubejax.analyses.plot` shares.

Nothing calls ``plt.show``; :func:`save_figure` writes PNG and PDF inside :func:`figure_style`
(TrueType fonts in the PDF, as journals ask, instead of Type 3).
"""

from __future__ import annotations

import contextlib
import contextvars
import logging
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt

from ...lp.evidence.registry import series_style, tube_methods

__all__ = ["save_figure", "new_axes", "figure_style", "FIGURE_RC", "PAPER_RC", "STYLES", "current_style",
           "paper_style", "COLUMN_WIDTHS", "PALETTE", "ZSHAPE_COLOURS",
           "series_colour", "number"]

#: The settings :func:`figure_style` applies: fonts embedded as TrueType (Type 42), not Type 3.
FIGURE_RC = {"pdf.fonttype": 42, "ps.fonttype": 42}
#: What the ``paper`` style adds: journal font sizes, thin lines, no top/right frame.
PAPER_RC = {"font.size": 8, "axes.titlesize": 8, "axes.labelsize": 8, "xtick.labelsize": 7,
            "ytick.labelsize": 7, "legend.fontsize": 7, "lines.linewidth": 1.2, "lines.markersize": 4,
            "axes.linewidth": 0.6, "savefig.pad_inches": 0.02}
#: ``paper``: titles say what is drawn, in one line, with no run log (the counts go in the caption);
#: ``draft``: titles carry the run's counts (what the apps printed). Both use :data:`PALETTE`.
STYLES = ("paper", "draft")
#: Journal column widths in inches (one column, two columns; IEEE-like, Elsevier and Springer are close).
COLUMN_WIDTHS = {1: 3.5, 2: 7.16}

#: Okabe-Ito, safe for the common colour-vision deficiencies; its yellow is left out (low contrast on white).
PALETTE = {"black": "#000000", "orange": "#E69F00", "sky": "#56B4E9", "green": "#009E73", "blue": "#0072B2",
           "vermillion": "#D55E00", "purple": "#CC79A7", "wine": "#882255", "olive": "#999933", "grey": "#777777"}
#: One colour per kind of ``Z`` (the tube method's series), in every plot; none is another method's colour
#: (a method's own colour is its record's, :func:`~tubejax.lp.evidence.registry.series_style`).
ZSHAPE_COLOURS = {"box": PALETTE["blue"], "diamond": PALETTE["green"], "cell": PALETTE["purple"],
                  "regular": PALETTE["orange"], "chamfer": PALETTE["sky"], "learned": PALETTE["wine"],
                  "learned_pair": PALETTE["olive"]}

_STYLE: contextvars.ContextVar = contextvars.ContextVar("tubejax_figure_style", default="draft")


def series_colour(method, zshape=None) -> str:
    """The fixed colour of a method's series: the tube method by its ``Z`` kind (:data:`ZSHAPE_COLOURS`),
    the others by their record (:func:`~tubejax.lp.evidence.registry.series_style`); an unknown one grey."""
    if str(method) in tube_methods() and zshape is not None:
        return ZSHAPE_COLOURS.get(str(zshape), PALETTE["grey"])
    return series_style(method).colour


def current_style() -> str:
    """The style figures are drawn in now: that of the innermost :func:`figure_style` block, else ``'draft'``."""
    return _STYLE.get()


def paper_style() -> bool:
    """Whether figures are drawn in the ``paper`` style now (short one-line titles, no run logs)."""
    return _STYLE.get() == "paper"


def number(x, fmt: str = ".3g") -> str:
    """``x`` formatted for a label, never as ``-0`` (a margin of ``-0.0`` reads ``0``)."""
    return format(float(x) + 0.0, fmt)


def figure_style(style: str | None = None):
    """A context in which figures are drawn and saved in this package's style (:data:`FIGURE_RC`; the
    ``rcParams`` change only inside the ``with`` block).

    Parameters
    ----------
    style : {'paper', 'draft'}, optional
        ``'paper'`` adds :data:`PAPER_RC` and makes the figures drawn inside the block use short
        one-line titles without run logs (:func:`paper_style`); ``None`` keeps the current style.
        Draw the figure inside the block, not only save it: sizes apply when text is created.

    Examples
    --------
    >>> with figure_style("paper"):
    ...     ax = plot_trajectories(decomp, result)      # doctest: +SKIP
    ...     save_figure(ax, "out", "fig7")              # doctest: +SKIP
    """
    if style is not None and style not in STYLES:
        raise ValueError(f"style: expected one of {', '.join(STYLES)}, got {style!r}")
    style = current_style() if style is None else style
    rc = dict(FIGURE_RC, **(PAPER_RC if style == "paper" else {}))
    return _quiet_fonts(matplotlib.rc_context(rc), style)


@contextlib.contextmanager
def _quiet_fonts(rc, style: str = "draft"):
    """``rc`` with fontTools' subsetting messages (one INFO line per table and font, hundreds per
    PDF with TrueType fonts) held at WARNING while inside it, and ``style`` the current style."""
    logger = logging.getLogger("fontTools")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    token = _STYLE.set(style)
    try:
        with rc:
            yield
    finally:
        _STYLE.reset(token)
        logger.setLevel(level)


def new_axes(figsize=(6, 6)):
    """A fresh ``(fig, ax)`` pair (Agg backend)."""
    return plt.subplots(figsize=figsize)


def _ax(ax, figsize=(6, 6)):
    return new_axes(figsize)[1] if ax is None else ax


def save_figure(fig, directory, stem: str, dpi: int = 150) -> tuple[Path, Path]:
    """Write ``directory/<stem>.png`` (at ``dpi``) and ``.pdf`` inside :func:`figure_style` (fonts as TrueType);
    returns both paths. ``fig``: a Figure or an Axes (its figure); ``directory`` is created if missing."""
    fig = getattr(fig, "figure", fig) if not hasattr(fig, "savefig") else fig
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    png, pdf = directory / f"{stem}.png", directory / f"{stem}.pdf"
    with figure_style():
        fig.savefig(png, dpi=dpi, bbox_inches="tight")
        fig.savefig(pdf, bbox_inches="tight")
    return png, pdf
