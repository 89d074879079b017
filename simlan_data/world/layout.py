"""Read SIMLAN's warehouse layout table (one placed model per row) and pick a fidelity level."""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path

import polars as pl

from simlan_data.constants import LAYOUT_DIR
from simlan_data.errors import AssetError
from simlan_data.world.models import MODEL_SPECS

FIDELITY_LEVELS = ("empty", "light", "medium", "default")
LAYOUT_COLUMNS = {
    "model": pl.String,
    "name": pl.String,
    "x_m": pl.Float64,
    "y_m": pl.Float64,
    "z_m": pl.Float64,
    "roll_rad": pl.Float64,
    "pitch_rad": pl.Float64,
    "yaw_rad": pl.Float64,
    "static": pl.Int64,
    "world_setups": pl.String,
}
MAX_LAYOUT_ROWS = 100_000


@dataclass(frozen=True)
class Placement:
    """One model placed in the world (SIMLAN's world file entry)."""

    model: str
    name: str
    xyz_m: tuple[float, float, float]
    rpy_rad: tuple[float, float, float]
    static: bool
    levels: frozenset[str]


def resolve_layout_path(path: str | Path) -> Path:
    """Return ``path`` as given if it exists, else relative to the packaged layouts."""
    p = Path(path)
    return p if p.is_file() or p.is_absolute() else LAYOUT_DIR / p


def load_layout(path: str | Path, fidelity: str) -> list[Placement]:
    """Return the placements of ``fidelity`` from a layout CSV.

    Raises:
        AssetError: the file is missing, malformed, or names an unknown fidelity level.
    """
    if fidelity not in FIDELITY_LEVELS:
        raise AssetError(
            f"unknown world.fidelity '{fidelity}'",
            "config",
            f"expected one of {', '.join(FIDELITY_LEVELS)}",
            f"set world.fidelity={FIDELITY_LEVELS[-1]}",
        )
    p = resolve_layout_path(path)
    if not p.is_file():
        raise AssetError(
            "layout file missing",
            str(p),
            "no such file",
            "set world.layout to a CSV like assets/layout/warehouse_layout.csv",
        )
    df = _read_layout_csv(p)
    _check_rows(df, p)
    return _placements(df, p, fidelity)


def _read_layout_csv(p: Path) -> pl.DataFrame:
    """Read the layout CSV; refuse one unreadable, lacking SIMLAN's columns or too large."""
    try:
        df = pl.read_csv(p, schema_overrides=LAYOUT_COLUMNS, n_rows=MAX_LAYOUT_ROWS + 1)
    except (pl.exceptions.PolarsError, OSError, UnicodeDecodeError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise AssetError(
            "layout file unreadable",
            str(p),
            first,
            "fix the CSV (columns: " + ", ".join(LAYOUT_COLUMNS) + ")",
        ) from err
    missing = [c for c in LAYOUT_COLUMNS if c not in df.columns]
    if missing:
        raise AssetError(
            "layout file lacks columns",
            str(p),
            ", ".join(missing),
            "use SIMLAN's layout columns: " + ", ".join(LAYOUT_COLUMNS),
        )
    if df.height > MAX_LAYOUT_ROWS:
        raise AssetError("layout file too large", str(p), f"over {MAX_LAYOUT_ROWS} rows", "split the layout")
    return df


def _check_rows(df: pl.DataFrame, p: Path) -> None:
    """Refuse a row with an empty or non-finite pose or model, or a model this twin has no geometry for."""
    numeric = ["x_m", "y_m", "z_m", "roll_rad", "pitch_rad", "yaw_rad"]
    bad = df.filter(
        pl.any_horizontal([pl.col(c).is_null() | ~pl.col(c).is_finite() for c in numeric])
        | pl.col("model").is_null()
    )
    if bad.height:
        row = bad.row(0, named=True)
        raise AssetError(
            "layout row invalid",
            f"{p} (model {row['model']!r}, name {row['name']!r})",
            "a pose value or the model is empty or not finite",
            "fill in x_m y_m z_m roll_rad pitch_rad yaw_rad",
        )
    unknown_models = sorted(set(df["model"].to_list()) - set(MODEL_SPECS))
    if unknown_models:
        name = unknown_models[0]
        close = difflib.get_close_matches(name, list(MODEL_SPECS), n=1)
        raise AssetError(
            f"layout names an unknown model {name!r}",
            str(p),
            f"this twin has no geometry for it ({len(unknown_models)} unknown: {', '.join(unknown_models[:5])})",
            f"did you mean {close[0]!r}?" if close else "use a model of simlan_data/world/models.py",
        )


def _placements(df: pl.DataFrame, p: Path, fidelity: str) -> list[Placement]:
    """Keep the rows of ``fidelity`` as placements; refuse a row naming an unknown fidelity level."""
    out: list[Placement] = []
    for row in df.iter_rows(named=True):
        levels = frozenset((row["world_setups"] or "").split())
        unknown = levels - set(FIDELITY_LEVELS)
        if unknown:
            raise AssetError(
                "layout row has an unknown fidelity level",
                f"{p} (name {row['name']!r})",
                ", ".join(sorted(unknown)),
                "use " + ", ".join(FIDELITY_LEVELS),
            )
        if fidelity not in levels:
            continue
        out.append(
            Placement(
                model=row["model"],
                name=row["name"] or row["model"],
                xyz_m=(row["x_m"], row["y_m"], row["z_m"]),
                rpy_rad=(row["roll_rad"], row["pitch_rad"], row["yaw_rad"]),
                static=row["static"] == 1,
                levels=levels,
            )
        )
    return out
