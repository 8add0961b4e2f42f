"""Plotly figures in self-contained HTML pages (shared by the validation and sweep reports).

A page carries plotly.js once, inline (:func:`plotlyjs_script`, about 4.8 MB), so it is one
file that works offline, and each figure as a ``<div class="plotly-graph-div">`` with its data
and a call to ``Plotly.newPlot`` (:func:`figure_div`). Lines are thinned to at most
:data:`MAX_POINTS` points (:func:`thin`) and stored as float32 (:func:`f32`). plotly is
imported on use only.
"""

from __future__ import annotations

import html
import json
from typing import Any

import numpy as np

__all__ = [
    "MARKER_SCRIPT",
    "MAX_POINTS",
    "PLOTLY_CONFIG",
    "f32",
    "figure_div",
    "minmax_indices",
    "plotlyjs_script",
    "thin",
]

#: Most points drawn per line (longer traces are thinned by a constant stride).
MAX_POINTS = 2000

#: Plotly options of every report figure: responsive, no logo, PNG export at 2×.
PLOTLY_CONFIG: dict[str, Any] = {
    "responsive": True,
    "displaylogo": False,
    "toImageButtonOptions": {"format": "png", "scale": 2},
}


#: After load, record on <body> how many figures there are (PNG images and interactive plots)
#: and how many are drawn: an image decoded and laid out with a non-zero size, a plot that
#: plotly.js has drawn (its container has the class js-plotly-plot and an svg.main-svg of
#: non-zero size). Read by clutchlab.validation.render in headless Chromium.
MARKER_SCRIPT = (
    "<script>window.addEventListener('load',function(){"
    "function shown(e){var r=e.getBoundingClientRect();return r.width>0&&r.height>0;}"
    "var im=Array.prototype.slice.call(document.images);"
    "var ok=im.filter(function(i){return i.complete&&i.naturalWidth>0&&shown(i);});"
    "var pl=Array.prototype.slice.call(document.querySelectorAll('.plotly-graph-div'));"
    "var dr=pl.filter(function(d){var s=d.querySelector('svg.main-svg');"
    "return d.classList.contains('js-plotly-plot')&&s!==null&&shown(s);});"
    "var b=document.body;"
    "b.setAttribute('data-figures',String(im.length+pl.length));"
    "b.setAttribute('data-figures-visible',String(ok.length+dr.length));"
    "b.setAttribute('data-plots',String(pl.length));"
    "b.setAttribute('data-plots-drawn',String(dr.length));"
    "b.setAttribute('data-page-height',String(document.documentElement.scrollHeight));});"
    "</script>"
)


def thin(n: int, max_points: int = MAX_POINTS) -> slice:
    """Stride that keeps at most ``max_points`` of ``n`` samples (first sample kept).

    Parameters
    ----------
    n : int
        Samples in the line.
    max_points : int
        Most samples kept.

    Returns
    -------
    slice
    """
    return slice(None, None, max(1, -(-n // max_points)))


def minmax_indices(y: Any, max_points: int = MAX_POINTS) -> np.ndarray:
    """Indices of at most ``max_points`` samples of ``y`` that keep its peaks.

    ``y`` is cut into ``max_points // 2`` consecutive buckets; of each, the samples with the
    smallest and the largest value are kept (in order), so a spike narrower than a bucket
    (a latch snap in a residual) survives the thinning, unlike a constant stride.

    Parameters
    ----------
    y : array_like
        The line's values (any unit); NaN allowed.
    max_points : int
        Most samples kept (at least 2).

    Returns
    -------
    numpy.ndarray
        Increasing integer indices; every index when ``len(y) <= max_points``.
    """
    y = np.asarray(y, dtype=float)
    n = y.size
    if n <= max_points:
        return np.arange(n)
    size = -(-n // max(1, max_points // 2))
    nb = -(-n // size)
    lo = np.full(nb * size, np.inf)
    hi = np.full(nb * size, -np.inf)
    finite = np.isfinite(y)
    lo[:n] = np.where(finite, y, np.inf)
    hi[:n] = np.where(finite, y, -np.inf)
    start = np.arange(nb) * size
    idx = np.concatenate(
        [start + lo.reshape(nb, size).argmin(1), start + hi.reshape(nb, size).argmax(1)]
    )
    return np.unique(np.minimum(idx, n - 1))


def f32(x: Any, sl: slice | np.ndarray = slice(None)) -> np.ndarray:
    """``x[sl]`` as a float32 array (half the size of float64 in the page).

    Parameters
    ----------
    x : array_like
        Values (any unit).
    sl : slice or numpy.ndarray
        Samples kept (a slice or indices).

    Returns
    -------
    numpy.ndarray
    """
    return np.asarray(x, dtype=float)[sl].astype(np.float32)


def plotlyjs_script() -> str:
    """plotly.js as one inline ``<script>`` element (about 4.8 MB), for the page's ``<head>``.

    Returns
    -------
    str
    """
    from plotly.offline import get_plotlyjs

    # "</script" cannot occur inside a script element; plotly.js has none, but be safe.
    return "<script>" + get_plotlyjs().replace("</script", "<\\/script") + "</script>"


def figure_div(fig: Any, div_id: str) -> str:
    """A figure as a ``<div class="plotly-graph-div">`` and the script that draws it.

    plotly.js must already be on the page (:func:`plotlyjs_script`). User-provided strings
    in the figure (variant and experiment names) are JSON-encoded with ``<``, ``>`` and ``&``
    escaped, so they cannot end the script element.

    Parameters
    ----------
    fig : plotly.graph_objects.Figure
        The figure.
    div_id : str
        ``id`` of the ``<div>`` (letters, digits, ``-`` and ``_``).

    Returns
    -------
    str
    """
    spec = fig.to_plotly_json()
    payload = _script_json([spec["data"], spec["layout"], PLOTLY_CONFIG])
    height = int(spec["layout"].get("height") or 450)
    return (
        f"<div id='{html.escape(div_id)}' class='plotly-graph-div' "
        f"style='height:{height}px;width:100%'></div>"
        f"<script>(function(){{var a={payload};"
        f"Plotly.newPlot({json.dumps(div_id)},a[0],a[1],a[2]);}})();</script>"
    )


def _script_json(obj: Any) -> str:
    from plotly.utils import PlotlyJSONEncoder

    text = json.dumps(obj, cls=PlotlyJSONEncoder, separators=(",", ":"))
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
