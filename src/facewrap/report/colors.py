"""Colours of the software renderer: colour maps, colour limits, sRGB conversions.

Colour maps are tables of sRGB colours; shading runs in linear light, so colours
are converted on the way in (:func:`srgb_to_linear`) and out
(:func:`linear_to_srgb8`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["COLORMAPS", "NAN_COLOR", "colormap", "color_limits", "apply_colormap",
           "colormap_lookup", "srgb_to_linear", "linear_to_srgb8", "as_rgb"]

# magma, coolwarm, turbo; CC0 / BSD), interpolated linearly to 256 entries.
_STOPS = {
    "viridis": "440154 48186a 472d7b 424086 3b528b 33638d 2c728e 26828e 21918c 1fa088 "
               "28ae80 3fbc73 5ec962 84d44b addc30 d8e219 fde725",
    "inferno": "000004 0b0724 210c4a 3d0965 57106e 71196e 8a226a a32c61 bc3754 d24644 "
               "e45a31 f1731d f98e09 fcac11 f9cb35 f2ea69 fcffa4",
    "magma": "000004 0a0822 1d1147 36106b 51127c 6a1c81 832681 9c2e7f b73779 d0416f "
             "e75263 f56b5c fc8961 fea772 fec488 fde2a3 fcfdbf",
    "coolwarm": "3b4cc0 4e68d8 6282ea 779af7 8db0fe a3c2fe b9d0f9 ccd9ed dddcdc ecd3c5 "
                "f5c4ac f7b093 f4987a eb7d62 dd5f4b ca3b37 b40426",
    "turbo": "30123b 4040a2 466be3 4294ff 28bceb 18ddc2 32f298 6dfe62 a4fc3c cdec34 "
             "eecf3a fdac34 fb7e21 eb500e d02f05 a91601 7a0403",
    "greys": "000000 ffffff",
}
#: Names accepted by :func:`colormap`.
COLORMAPS = tuple(_STOPS)


_CLAY = (0.78, 0.74, 0.70)           # default surface colour (sRGB, neutral clay)
#: Colour of NaN values (e.g. points not covered), sRGB.
NAN_COLOR = (0.55, 0.55, 0.55)


def colormap(cmap="viridis", n: int = 256) -> np.ndarray:
    """A colour map as a table of sRGB colours.

    Parameters
    ----------
    cmap : str or (k, 3) float array_like
        A name of :data:`COLORMAPS` (``"viridis"``, ``"inferno"``, ``"magma"``:
        perceptually uniform, lightness increasing; ``"coolwarm"``: diverging, for
        signed values; ``"turbo"``; ``"greys"``), optionally ending in ``"_r"`` for
        the reversed map, or your own stops in [0, 1] (k >= 2).
    n : int
        Entries of the table.

    Returns
    -------
    (n, 3) float64
        sRGB colours in [0, 1], from the low end to the high end.

    Examples
    --------
    >>> np.round(colormap("greys", 3), 3).tolist()
    [[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [1.0, 1.0, 1.0]]
    """
    if isinstance(cmap, str):
        name, rev = (cmap[:-2], True) if cmap.endswith("_r") else (cmap, False)
        if name not in _STOPS:
            raise ValueError(f"cmap must be one of {list(COLORMAPS)} (optionally with "
                             f"'_r') or a (k, 3) array, got {cmap!r}")
        stops = np.array([[int(h[i:i + 2], 16) for i in (0, 2, 4)]
                          for h in _STOPS[name].split()]) / 255.0
        if rev:
            stops = stops[::-1]
    else:
        stops = np.asarray(cmap, dtype=np.float64)
        if (stops.ndim != 2 or stops.shape[1] != 3 or len(stops) < 2
                or not np.all((stops >= 0) & (stops <= 1))):
            raise ValueError("a custom cmap must be a (k, 3) array of colours in [0, 1], "
                             "k >= 2")
    s = np.linspace(0.0, 1.0, len(stops))
    t = np.linspace(0.0, 1.0, int(n))
    return np.stack([np.interp(t, s, stops[:, c]) for c in range(3)], axis=1)


def color_limits(values: np.ndarray, clim) -> tuple[float, float]:
    """Values mapped to the two ends of a colour map: ``clim`` checked, or the range.

    Parameters
    ----------
    values : (k,) float64
        Used when ``clim`` is None: their finite range (widened by 0.5 each way
        when it is a single value; ``(0, 1)`` when there is no finite value).
    clim : (lo, hi) or None
        Finite, ``lo < hi``.

    Returns
    -------
    (float, float)

    Examples
    --------
    >>> color_limits(np.array([2.0, np.nan, 5.0]), None), color_limits(np.zeros(0), (0, 1))
    ((2.0, 5.0), (0.0, 1.0))
    """
    if clim is not None:
        lo, hi = (float(c) for c in clim)
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise ValueError(f"clim must be two finite numbers lo < hi, got {clim!r}")
        return lo, hi
    finite = values[np.isfinite(values)]
    if len(finite) == 0:
        return 0.0, 1.0
    lo, hi = float(finite.min()), float(finite.max())
    return (lo, hi) if hi > lo else (lo - 0.5, lo + 0.5)


def apply_colormap(values, cmap="viridis", clim=None, nan_color=NAN_COLOR) -> np.ndarray:
    """sRGB colours of scalar values.

    Parameters
    ----------
    values : (k,) float
        NaN values get ``nan_color``.
    cmap : str or (k, 3) float
        See :func:`colormap`.
    clim : (lo, hi), optional
        Values mapped to the two ends (clipped beyond); default the finite range.
    nan_color : (3,) float

    Returns
    -------
    (k, 3) float64 in [0, 1]

    Examples
    --------
    >>> apply_colormap([0.0, 2.0, np.nan], "greys", (0, 1), nan_color=(1, 0, 0)).tolist()
    [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.0, 0.0]]
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    lo, hi = color_limits(v, clim)
    lut = colormap(cmap)
    out = colormap_lookup(v, lut, lo, hi)
    out[~np.isfinite(v)] = np.asarray(nan_color, dtype=np.float64)
    return out


def colormap_lookup(v: np.ndarray, lut: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Linear interpolation in a colour table, values clipped to ``[lo, hi]``.

    Parameters
    ----------
    v : (k,) float64
    lut : (m, 3) float64
        A table of :func:`colormap`.
    lo, hi : float
        Values at the two ends, ``lo < hi``.

    Returns
    -------
    (k, 3) float64
        NaN values come out as entry 0.
    """
    n = len(lut)
    s = np.nan_to_num((v - lo) / (hi - lo), nan=0.0, posinf=1.0, neginf=0.0)
    s = np.clip(s, 0.0, 1.0) * (n - 1)
    i = np.minimum(s.astype(np.int64), n - 2)
    f = (s - i)[:, None]
    return lut[i] * (1.0 - f) + lut[i + 1] * f



# -- sRGB ------------------------------------------------------------------------------------

def srgb_to_linear(c):
    """Linear light of sRGB values in [0, 1], any shape (float64)."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


# linear light -> sRGB uint8 by table (faster than a power per pixel, and exact to
# within rounding: the steepest step of the curve is below 1/8 of an 8-bit level)
_LUT_SIZE = 1 << 14
_SRGB_LUT = np.clip(np.rint(_linear_to_srgb(np.linspace(0.0, 1.0, _LUT_SIZE)) * 255),
                    0, 255).astype(np.uint8)


def linear_to_srgb8(c: np.ndarray) -> np.ndarray:
    """uint8 sRGB of linear-light values (any shape, clipped to [0, 1]), by table."""
    i = np.rint(np.clip(c, 0.0, 1.0) * (_LUT_SIZE - 1)).astype(np.int32)
    return _SRGB_LUT[i]


def as_rgb(c, name: str) -> np.ndarray:
    """A colour argument as an sRGB triple, checked.

    Parameters
    ----------
    c : str or (3,) float or (3,) uint8
        A name ("white", "black", "clay", "grey"), ``"#rrggbb"``, a float triple in
        [0, 1] or an integer triple in [0, 255].
    name : str
        The argument's name, for the error message.

    Returns
    -------
    (3,) float64 in [0, 1]

    Examples
    --------
    >>> as_rgb("#ff0000", "color").tolist(), as_rgb((0, 0, 255), "color").tolist()
    ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    """
    named = {"white": (1.0, 1.0, 1.0), "black": (0.0, 0.0, 0.0),
             "clay": _CLAY, "grey": (0.5, 0.5, 0.5), "gray": (0.5, 0.5, 0.5)}
    if isinstance(c, str):
        if c in named:
            return np.array(named[c])
        if c.startswith("#") and len(c) == 7:
            return np.array([int(c[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
        raise ValueError(f"{name} must be a name in {sorted(named)}, '#rrggbb' or an "
                         f"RGB triple, got {c!r}")
    a = np.asarray(c, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be an RGB triple, got {c!r}")
    if np.issubdtype(np.asarray(c).dtype, np.integer) or a.max() > 1:
        a = a / 255.0
    return np.clip(a, 0.0, 1.0)

