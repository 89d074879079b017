"""Semantic segmentation classes: id -> name and colour. Pallet truck 51 and forklift 50 as in SIMLAN.

Rendered segmentation images carry these ids (uint8); 0 means no valid ray or nothing seen.
The table is recorded in every recording (``/simlan/semantic_labels``). The colours are the one
source of every view of the labels: the palette of the recorded label PNGs (a viewer that decodes
PNG shows these colours; ``recording/codecs.py``) and the Rerun export's annotation context
(``viz/rerun_export.py``). Each class has its own colour, so a colour maps back to its class.
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

UNLABELED = 0

SEMANTIC_CLASSES: MappingProxyType[str, int] = MappingProxyType(
    {
        "unlabeled": UNLABELED,
        "floor": 1,
        "wall": 2,
        "floor_marking": 3,
        "shelf": 10,
        "box": 11,
        "pallet": 12,
        "railing": 13,
        "pole": 14,
        "furniture": 15,
        "vehicle": 16,
        "forklift": 50,
        "pallet_truck": 51,
        "jackal": 52,
        "humanoid": 53,
        "panda": 54,
    }
)

LABEL_NAMES: MappingProxyType[int, str] = MappingProxyType({v: k for k, v in SEMANTIC_CLASSES.items()})

# class id -> sRGB colour (Cityscapes' where a class has a counterpart: floor as road, person red)
LABEL_COLOURS: MappingProxyType[int, tuple[int, int, int]] = MappingProxyType(
    {
        SEMANTIC_CLASSES["unlabeled"]: (0, 0, 0),
        SEMANTIC_CLASSES["floor"]: (128, 64, 128),
        SEMANTIC_CLASSES["wall"]: (102, 102, 156),
        SEMANTIC_CLASSES["floor_marking"]: (250, 250, 250),
        SEMANTIC_CLASSES["shelf"]: (70, 130, 180),
        SEMANTIC_CLASSES["box"]: (190, 153, 153),
        SEMANTIC_CLASSES["pallet"]: (152, 251, 152),
        SEMANTIC_CLASSES["railing"]: (180, 165, 180),
        SEMANTIC_CLASSES["pole"]: (153, 153, 153),
        SEMANTIC_CLASSES["furniture"]: (107, 142, 35),
        SEMANTIC_CLASSES["vehicle"]: (0, 0, 142),
        SEMANTIC_CLASSES["forklift"]: (255, 128, 0),
        SEMANTIC_CLASSES["pallet_truck"]: (0, 200, 255),
        SEMANTIC_CLASSES["jackal"]: (255, 220, 0),
        SEMANTIC_CLASSES["humanoid"]: (220, 20, 60),
        SEMANTIC_CLASSES["panda"]: (119, 11, 32),
    }
)
UNKNOWN_LABEL_COLOUR = (255, 0, 255)  # an id that is no class (none is rendered)


def label_id(name: str) -> int:
    """Return the class id of ``name`` (KeyError names the known classes)."""
    try:
        return SEMANTIC_CLASSES[name]
    except KeyError:
        raise KeyError(f"unknown semantic class {name!r}; known: {', '.join(SEMANTIC_CLASSES)}") from None


def label_palette(entries: int = max(LABEL_NAMES) + 1) -> NDArray[np.uint8]:
    """The colour of every id below ``entries`` (``entries`` x 3, uint8 RGB): entry i is the
    colour of class i, :data:`UNKNOWN_LABEL_COLOUR` for an id that is no class."""
    palette = np.empty((entries, 3), dtype=np.uint8)
    palette[:] = UNKNOWN_LABEL_COLOUR
    for i, colour in LABEL_COLOURS.items():
        if i < entries:
            palette[i] = colour
    return palette
