"""Identities of sample faces: a handful of feature parameters drawn from a seed.

Head size, nose length/width/projection, eye spacing, mouth width, lip fullness, jaw
width, chin, cheekbones, brow ridge and skin tone; seed 0 (or None) is the
template's own face.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

__all__ = ["Identity", "face_identity"]


@dataclass(frozen=True)
class Identity:
    """Feature parameters of one face (defaults = the template's face).

    Lengths in mm, the rest are multipliers of the default feature sizes.
    """

    width: float = 1.0          # head scale along x
    height: float = 1.0         # head scale along y
    depth: float = 1.0          # head scale along z
    eye_spacing: float = 0.0    # mm moved outward by each eye
    nose_length: float = 0.0    # mm moved down by the nose tip
    nose_width: float = 0.0     # mm moved outward by each ala
    nose_projection: float = 1.0
    mouth_width: float = 0.0    # mm moved outward by each mouth corner
    lip_fullness: float = 1.0
    jaw_width: float = 1.0
    chin: float = 1.0
    cheekbones: float = 1.0
    brow_ridge: float = 1.0
    skin: float = 0.0           # skin tone shift for the texture (-1 darker .. 1 lighter)


_IDENTITY_SD = Identity(width=0.04, height=0.035, depth=0.04, eye_spacing=1.8,
                         nose_length=2.5, nose_width=1.5, nose_projection=0.12,
                         mouth_width=2.0, lip_fullness=0.2, jaw_width=0.25, chin=0.25,
                         cheekbones=0.25, brow_ridge=0.25, skin=0.5)


def face_identity(seed: int | None) -> Identity:
    """The face of ``seed``: defaults for 0/None, else drawn around them (+-2 sd)."""
    if seed is None or seed == 0:
        return Identity()
    z = np.clip(np.random.default_rng(seed).standard_normal(len(fields(Identity))),
                -2.0, 2.0)
    base = Identity()
    return Identity(**{f.name: getattr(base, f.name) + k * getattr(_IDENTITY_SD, f.name)
                        for f, k in zip(fields(Identity), z.tolist())})
