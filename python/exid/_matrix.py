"""Comparison matrices from Python: run one, read its SQLite results into pandas."""

from __future__ import annotations

import json
import os
import sqlite3
from typing import TYPE_CHECKING, Any, Dict, Optional, Union

from . import _exid

if TYPE_CHECKING:  # pandas is imported by read_matrix alone
    import pandas

PathLike = Union[str, "os.PathLike[str]"]


def run_matrix(
    matrix: PathLike,
    out: Optional[PathLike] = None,
    *,
    jobs: int = 1,
    retry_failed: bool = False,
    force: bool = False,
) -> Dict[str, Any]:
    """Runs a comparison matrix (a matrix YAML file) as ``exid matrix`` does: each cell in its
    own process, ``jobs`` at a time, results in ``out``/results.sqlite (default
    out/<matrix name>); finished cells are skipped unless ``force``. Returns the counts (total,
    ok, failed, timeout, skipped, not_run), ``wall_s``, ``out`` and ``database``."""
    return _exid.run_matrix(
        os.fspath(matrix), os.fspath(out) if out is not None else "", int(jobs), retry_failed, force
    )


def read_matrix(
    source: PathLike, *, metrics: bool = True, summary: bool = False
) -> "pandas.DataFrame":
    """A matrix's results (a folder holding results.sqlite, or the database itself) as a pandas
    DataFrame, one row per cell run: run_id, matrix, cell, label, status, message, wall_s,
    started, finished, hash, then one column per axis (the value's label, as in ``exid matrix
    table``), then (``metrics``) one column per metric (numbers as float, text as str, missing
    as NaN). ``summary`` adds the cell's summary.json as a dict (column ``summary``)."""
    import pandas as pd

    path = os.fspath(source)
    if os.path.isdir(path):
        path = os.path.join(path, "results.sqlite")
    if not os.path.isfile(path):
        raise _exid.Error(f"{path}: no matrix database (results.sqlite of `exid matrix --out DIR`)")
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        cols = "id AS run_id, matrix, cell, label, status, message, wall_s, started, finished, hash"
        if summary:
            cols += ", summary"
        try:
            runs = pd.read_sql_query(
                f"SELECT {cols} FROM runs ORDER BY id",
                con,
            )
            axes = pd.read_sql_query("SELECT run_id, axis, value FROM axes", con)
            mets = (
                pd.read_sql_query("SELECT run_id, name, type, real, text FROM metrics", con)
                if metrics
                else None
            )
        except (sqlite3.DatabaseError, pd.errors.DatabaseError) as e:
            raise _exid.Error(f"{path}: not a matrix database ({e})") from e
    finally:
        con.close()
    df = runs.set_index("run_id")
    if not axes.empty:
        wide = axes.groupby(["run_id", "axis"])["value"].first().unstack()
        wide.columns.name = None
        df = df.join(wide[[c for c in wide.columns if c not in df.columns]])
    if mets is not None and not mets.empty:
        num = mets[mets["type"] != "text"]
        txt = mets[mets["type"] == "text"]
        parts = []
        if not num.empty:
            parts.append(num.groupby(["run_id", "name"])["real"].first().unstack())
        if not txt.empty:
            parts.append(txt.groupby(["run_id", "name"])["text"].first().unstack())
        for p in parts:
            p.columns.name = None
            df = df.join(p[[c for c in p.columns if c not in df.columns]])
    if summary and "summary" in df.columns:
        df["summary"] = [json.loads(s) if isinstance(s, str) and s else None for s in df["summary"]]
    return df.reset_index()
