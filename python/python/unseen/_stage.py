"""What the stage comparisons of unseen.testing share."""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StageMistake:
    """A known way to get a stage wrong: its ``name`` (what the emulation is called by) and
    the ``text`` a report names it with."""

    name: str
    text: str


def ellipse_mask(shape, rng, r_min, r_div):
    """A filled axis-aligned ellipse of a seeded case's mask: centre anywhere in ``shape``,
    semi-axes between ``r_min`` and the side over ``r_div``."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    cy, cx = rng.uniform(0, h), rng.uniform(0, w)
    ry, rx = rng.uniform(r_min, h / r_div), rng.uniform(r_min, w / r_div)
    return (yy - cy) ** 2 / ry ** 2 + (xx - cx) ** 2 / rx ** 2 < 1
