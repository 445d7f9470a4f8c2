"""Figure style, fresh axes and saving: what every figure of :mod:`tubejax.analyses.plot` shares.

Nothing calls ``plt.show``; :func:`save_figure` writes PNG and PDF inside :func:`figure_style`
(TrueType fonts in the PDF, as journals ask, instead of Type 3).
"""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt

__all__ = ["save_figure", "new_axes", "figure_style", "FIGURE_RC"]

#: The settings :func:`figure_style` applies: fonts embedded as TrueType (Type 42), not Type 3.
FIGURE_RC = {"pdf.fonttype": 42, "ps.fonttype": 42}


def figure_style():
    """A context in which figures are drawn and saved in this package's style (:data:`FIGURE_RC`).

    It changes ``matplotlib.rcParams`` only inside the ``with`` block (nothing is set at
    import); :func:`save_figure` saves inside it.

    Examples
    --------
    >>> with figure_style():
    ...     fig.savefig("fig.pdf")          # doctest: +SKIP
    """
    return _quiet_fonts(matplotlib.rc_context(FIGURE_RC))


@contextlib.contextmanager
def _quiet_fonts(rc):
    """``rc`` with fontTools' subsetting messages (one INFO line per table and font, hundreds per
    PDF with TrueType fonts) held at WARNING while inside it."""
    logger = logging.getLogger("fontTools")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    try:
        with rc:
            yield
    finally:
        logger.setLevel(level)


def new_axes(figsize=(6, 6)):
    """A fresh ``(fig, ax)`` pair (Agg backend)."""
    fig, ax = plt.subplots(figsize=figsize)
    return fig, ax


def _ax(ax, figsize=(6, 6)):
    if ax is None:
        _, ax = new_axes(figsize)
    return ax


def save_figure(fig, directory, stem: str, dpi: int = 150) -> tuple[Path, Path]:
    """Write ``directory/<stem>.png`` and ``directory/<stem>.pdf``; returns both paths.

    Saved inside :func:`figure_style`: the PDF embeds its fonts as TrueType (Type 42).

    Parameters
    ----------
    fig : Figure or Axes
        An ``Axes`` stands for its figure.
    directory : path
        Created if missing.
    stem : str
    dpi : int
        Resolution of the PNG (the PDF is vector graphics).

    Returns
    -------
    (Path, Path)
        The PNG and the PDF.
    """
    fig = getattr(fig, "figure", fig) if not hasattr(fig, "savefig") else fig
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    png, pdf = directory / f"{stem}.png", directory / f"{stem}.pdf"
    with figure_style():
        fig.savefig(png, dpi=dpi, bbox_inches="tight")
        fig.savefig(pdf, bbox_inches="tight")
    return png, pdf
