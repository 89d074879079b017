"""Semantic segmentation classes: id -> name. Pallet truck 51 and forklift 50 as in SIMLAN.

Rendered segmentation images carry these ids (uint8); 0 means no valid ray or nothing seen.
The table is recorded in every recording (``/simlan/semantic_labels``).
"""

from __future__ import annotations

from types import MappingProxyType

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


def label_id(name: str) -> int:
    """Return the class id of ``name`` (KeyError names the known classes)."""
    try:
        return SEMANTIC_CLASSES[name]
    except KeyError:
        raise KeyError(f"unknown semantic class {name!r}; known: {', '.join(SEMANTIC_CLASSES)}") from None
