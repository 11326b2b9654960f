"""Files of a locator run: the epoch table, its metadata, figures, and error-model files.

A run folder (``locator run --out DIR``) holds::

    epochs.parquet | epochs.csv   one row per epoch (columns: locator.run.run_locator)
    run.json                      format, software version, configuration, source, summary
    interval_time.png             interval and estimate against time, trusted counts
    interval_chainage.png         the same along the line
    interval_lengths.png          histogram of claimed interval lengths per mode

``locator evaluate`` adds ``scored.parquet|csv`` (truth, error, HMI columns),
``evaluation.json`` and redraws the figures relative to the truth.

Error-model files (``locator calibrate --out FILE.json``) are read and written by
:mod:`predisat.gnss.errormodel`.
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping
from pathlib import Path

import pandas as pd

from locator.sim.simfile import read_folder_table
from predisat import __version__
from predisat.atomic import staged_folder, write_bytes_atomic
from predisat.jsontypes import JsonDict, strict_json_text

__all__ = [
    "FORMATS",
    "RUN_FORMAT",
    "RunFileError",
    "read_run",
    "read_table",
    "write_figures",
    "write_run",
    "write_table",
]

RUN_FORMAT = "locator-run/1"
FORMATS = ("parquet", "csv")
"""Table formats of a run folder."""


class RunFileError(ValueError):
    """A run folder or error-model file that cannot be read; the message names the fix."""


def _write_json(path: Path, data: Mapping[str, object]) -> None:
    # NaN (e.g. the interval median of a run without a claim) becomes null
    write_bytes_atomic(path, strict_json_text(data).encode())


def write_table(df: pd.DataFrame, folder: Path, name: str, fmt: str) -> Path:
    """Write ``name.parquet`` or ``name.csv`` atomically (removing the other format)."""
    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {FORMATS}, got {fmt!r}")
    for ext in FORMATS:
        (folder / f"{name}.{ext}").unlink(missing_ok=True)
    path = folder / f"{name}.{fmt}"
    if fmt == "parquet":
        buf = io.BytesIO()
        df.to_parquet(buf, index=False)
        write_bytes_atomic(path, buf.getvalue())
    else:
        write_bytes_atomic(path, df.to_csv(index=False, float_format="%.10g").encode())
    return path


def read_table(folder: Path, name: str) -> pd.DataFrame:
    """``name.parquet`` or ``name.csv`` from ``folder``."""
    return read_folder_table(folder, name, RunFileError, "`locator run`")


# What `locator evaluate` adds to a run folder (module docstring).
_EVALUATION_FILES = ("scored.parquet", "scored.csv", "evaluation.json", "stanford.png")


def write_run(
    epochs: pd.DataFrame,
    folder: str | Path,
    meta: Mapping[str, object],
    fmt: str = "parquet",
    figures_title: str | None = None,
    figures_banner: str | None = None,
) -> Path:
    """Write a run folder (table, ``run.json`` and, with ``figures_title``, the figures of
    :func:`write_figures`, ``figures_banner`` over each); returns the folder.

    The files are written in a staging folder and published together, ``run.json`` (which
    :func:`read_run` needs) withdrawn first and published last: written in place, a full disk
    left a new table beside the previous run's ``run.json`` and figures, which ``locator
    evaluate`` scored under the old trust rule (a user trial). An earlier run's table in the
    other format and its scoring (``scored``, ``evaluation.json``, ``stanford.png``) are
    removed: they described other epochs. Another process writing the folder is refused
    (:func:`predisat.atomic.exclusive_folder`).
    """
    out = Path(folder)
    stale = tuple(f"epochs.{ext}" for ext in FORMATS) + _EVALUATION_FILES
    with staged_folder(out, last=("run.json",), remove=stale) as stage:
        write_table(epochs, stage, "epochs", fmt)
        run = {"format": RUN_FORMAT, "software_version": __version__, **meta}
        _write_json(stage / "run.json", run)
        if figures_title is not None:
            write_figures(epochs, stage, title=figures_title, banner=figures_banner)
    return out


def read_run(folder: str | Path) -> tuple[pd.DataFrame, JsonDict]:
    """The epoch table and metadata of a run folder."""
    f = Path(folder)
    meta_path = f / "run.json"
    if not meta_path.is_file():
        raise RunFileError(f"{f}: no run.json; give the folder written by `locator run --out`")
    try:
        meta = json.loads(meta_path.read_text())
    except json.JSONDecodeError as exc:
        raise RunFileError(f"{meta_path}: not valid JSON ({exc}); rerun `locator run`") from exc
    if meta.get("format") != RUN_FORMAT:
        raise RunFileError(f"{meta_path}: format {meta.get('format')!r} is not {RUN_FORMAT!r}")
    epochs = read_table(f, "epochs")
    if "claim" in epochs and epochs["claim"].dtype != bool:
        for col in ("claim", "claim_fix", "safety_claim"):
            if col in epochs:  # safety_claim: not in run folders of older versions
                epochs[col] = epochs[col].astype(str).str.lower().isin(("true", "1"))
    return epochs, meta


def write_figures(
    epochs: pd.DataFrame, folder: str | Path, title: str = "", banner: str | None = None
) -> list[Path]:
    """The PNG figures of a run: interval against time and chainage, lengths, and, when the
    table is scored (``truth_m`` present: relative to the truth), the Stanford diagram; each
    names the constellations the run received; ``banner`` as :func:`locator.plots.run_figures`
    writes it."""
    # lazy: matplotlib only for the figures; reading and writing run tables must not import it
    from locator import plots

    out = Path(folder)
    figs = plots.run_figures(epochs, title, banner)
    paths = []
    for name, fig in figs.items():
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100)
        write_bytes_atomic(out / name, buf.getvalue())
        paths.append(out / name)
    return paths


