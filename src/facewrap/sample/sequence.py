"""Expression sequences of sample scans (4-D capture), one topology per frame."""

from __future__ import annotations

from facewrap.sample.scan import SampleScan, checked_transform, make_scan
from facewrap.sample.surface import checked_weights
from facewrap.sample.template import SampleTemplate, checked_resolution, make_template

__all__ = ["make_sequence"]


def make_sequence(template: SampleTemplate | None = None, frames: int = 10,
                  peak: dict[str, float] | None = None, **scan_kwargs) -> list[SampleScan]:
    """An expression ramp from neutral to ``peak``, one scan per frame (4-D capture).

    Frame ``f`` of ``frames`` has weights ``peak * f / (frames - 1)`` and is sampled
    with seed ``seed + f``, so every frame has its own topology.  The head pose is
    the same in every frame (``transform=True`` is drawn once, from ``seed``).

    Parameters
    ----------
    template : SampleTemplate, optional
        Default ``make_template()``.
    frames : int, default 10
        Number of scans, >= 2.
    peak : dict of str to float, optional
        Weights of the last frame (default: :func:`make_scan`'s default).
    **scan_kwargs
        Passed to :func:`make_scan` (``identity_seed``, ``resolution``, ``noise``,
        ``seed``...); not ``weights``.

    Returns
    -------
    list of SampleScan

    Examples
    --------
    >>> seq = make_sequence(make_template(24), frames=3, peak={"smile": 1.0},
    ...                     resolution=24, texture_size=8)
    >>> [s.weights["smile"] for s in seq]
    [0.0, 0.5, 1.0]
    >>> len({s.mesh.n_vertices for s in seq}) > 1
    True
    """
    if "weights" in scan_kwargs:
        raise ValueError("make_sequence: give the last frame's weights as peak=, "
                         "not weights=")
    frames = checked_resolution(frames, "frames", low=2)
    peak = checked_weights(peak)
    template = make_template() if template is None else template
    seed = int(scan_kwargs.pop("seed", 0))
    transform = checked_transform(scan_kwargs.pop("transform", True), seed)
    out = []
    for f in range(frames):
        k = f / (frames - 1)
        w = {name: value * k for name, value in peak.items()}
        out.append(make_scan(template, weights=w, seed=seed + f, transform=transform,
                             **scan_kwargs))
    return out
