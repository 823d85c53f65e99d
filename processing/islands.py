"""Drop small isolated islands of valid pixels: specks in unlit or low-modulation background.

Around a lit object, a few background pixels (a dark curtain, the table edge, the image border)
pass the modulation threshold by chance, and their phase decodes to points far in front of or
behind the object. They form small islands not connected to the object's valid region.

Criterion: the valid pixels are split into 8-connected regions; a region with fewer pixels than
``min_fraction`` of the largest region is dropped. Scale-free (the same fraction at any image
size or downsampling); several objects of comparable size all stay.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

DEFAULT_MIN_FRACTION = 0.005


def island_mask(valid: np.ndarray, min_fraction: float = DEFAULT_MIN_FRACTION) -> np.ndarray:
    """Pixels of ``valid`` that belong to islands smaller than ``min_fraction`` of the largest region.

    Parameters
    ----------
    valid : (H, W) bool array
    min_fraction : float in [0, 1]
        Regions below this fraction of the largest region's pixel count are islands; 0 keeps all.

    Returns
    -------
    (H, W) bool array, True on the islands (a subset of ``valid``).
    """
    if not 0.0 <= min_fraction <= 1.0:
        raise ValueError(f"min_fraction: expected a fraction in [0, 1], found {min_fraction}")
    valid = np.asarray(valid, dtype=bool)
    labels, count = ndimage.label(valid, structure=np.ones((3, 3), dtype=bool))
    if count <= 1:
        return np.zeros_like(valid)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    sizes[0] = 0
    small = sizes < min_fraction * sizes.max()
    small[0] = False
    return small[labels]
