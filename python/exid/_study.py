"""Studies from Python: run one (or one of its stages) and get its results as Python objects."""

from __future__ import annotations

import csv
import json
import logging
import os
import time
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, NamedTuple, Optional, Tuple, Union

import numpy as np

from . import _exid
from ._robot import _params_text

PathLike = Union[str, "os.PathLike[str]"]
Study = Union[PathLike, Mapping[str, Any]]

_STAGES = ("excite", "simulate", "identify")

#: The study's progress, one INFO record per step (stage, percent, text); see run_study.
logger = logging.getLogger("exid")


class StudyError(_exid.Error):
    """A study that ran and failed (or was cancelled): exid's message, and the
    :class:`StudyResult` (``.result``) with what the finished stages produced."""

    def __init__(self, message: str, result: "StudyResult") -> None:
        super().__init__(message)
        self.result = result


class EstimatedParameter(NamedTuple):
    """An identified base parameter: value, standard deviation (sigma) and nominal value."""

    name: str
    expression: str
    value: float
    std: float
    nominal: float


@dataclass
class Trajectory:
    """Samples of a trajectory: t (N,), q, qd, qdd (N, dof), measured coordinates."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


@dataclass
class Dataset:
    """An experiment's data: t (N,), q, qd, qdd, tau (N, dof); wrench (N, 6) or None."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: Optional[np.ndarray] = None
    wrench: Optional[np.ndarray] = None


@dataclass
class Validation:
    """The identified model on held-out data: its metrics (``relative_error``, per joint) and,
    row by row, the measured and predicted values of each equation (``equation`` indexes
    ``equations``; for the differential model, one equation per joint's torque)."""

    relative_error: float
    metrics: Dict[str, Any]
    equations: List[str]
    t: Optional[np.ndarray] = None
    equation: Optional[np.ndarray] = None
    measured: Optional[np.ndarray] = None
    predicted: Optional[np.ndarray] = None

    def of_equation(self, i: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t, measured, predicted) of equation ``i``."""
        if self.equation is None:
            raise ValueError("the study wrote no validation rows (validation.csv)")
        sel = self.equation == i
        return self.t[sel], self.measured[sel], self.predicted[sel]


@dataclass
class StudyResult:
    """What a study produced.

    ``summary`` is its summary.json as a dict (every figure the report shows); ``out`` the
    folder it wrote (None when :func:`run_study` ran it in a temporary folder, since removed).
    ``parameters`` are the identified base parameters with their sigma (``values``, ``std``
    and ``nominal`` as arrays, ``names`` in the same order); ``covariance`` is the estimate's
    covariance (base x base, in the order of ``names``; ``std = sqrt(diag(covariance))``) and
    ``correlation`` the same normalised (unit diagonal); both None without an identification.
    ``validation``, ``experiment``, ``trajectory`` (the optimal excitation) and
    ``initial_trajectory`` are None when the study has no such stage.

    ``experiment`` is read from experiment.csv, which a study writes for simulated data always
    but for RECORDED data only up to 100,000 samples (report.params.experiment_csv ``auto``: the
    file would be a copy of the input); above, ``experiment`` is None and
    ``summary["experiment"]["csv_not_written"]`` says why. To have the samples, run the study
    with ``report: {params: {experiment_csv: always}}`` (then ``experiment`` holds them), or
    read a kept experiment.csv (``out=``) with :func:`read_dataset`.

    ``tables`` holds every CSV table the study wrote (parameters.csv, covariance.csv,
    experiment.csv, validation.csv, the trajectories and histories), by file name, as dicts of
    column arrays (float, or str for a text column such as ``name``): ``pandas.DataFrame(
    res.tables["parameters.csv"])`` is the CSV file. In Jupyter the result shows itself as a
    table of its key figures, its parameters and the validation figure.
    """

    name: str
    status: str
    message: str
    summary: Dict[str, Any]
    out: Optional[Path]
    parameters: List[EstimatedParameter] = field(default_factory=list)
    validation: Optional[Validation] = None
    experiment: Optional[Dataset] = None
    trajectory: Optional[Trajectory] = None
    initial_trajectory: Optional[Trajectory] = None
    tables: Dict[str, Dict[str, np.ndarray]] = field(default_factory=dict)
    covariance: Optional[np.ndarray] = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def correlation(self) -> Optional[np.ndarray]:
        """The estimate's correlation matrix: covariance[i, j] / (std_i std_j), unit diagonal
        (NaN on the row and column of a parameter of zero variance); None without covariance."""
        if self.covariance is None:
            return None
        d = np.sqrt(np.diag(self.covariance))
        with np.errstate(divide="ignore", invalid="ignore"):
            c = self.covariance / np.outer(d, d)
        np.fill_diagonal(c, np.where(d > 0, 1.0, np.nan))
        return c

    def _repr_html_(self) -> str:
        from ._display import result_html

        return result_html(self)

    def _repr_markdown_(self) -> str:
        from ._display import result_markdown

        return result_markdown(self)

    @property
    def names(self) -> List[str]:
        return [p.name for p in self.parameters]

    @property
    def values(self) -> np.ndarray:
        return np.array([p.value for p in self.parameters])

    @property
    def std(self) -> np.ndarray:
        return np.array([p.std for p in self.parameters])

    @property
    def nominal(self) -> np.ndarray:
        return np.array([p.nominal for p in self.parameters])

    def __repr__(self) -> str:
        bits = [f"status {self.status}"]
        if self.parameters:
            bits.append(f"{len(self.parameters)} parameters")
        if self.validation is not None:
            bits.append(f"validation relative error {self.validation.relative_error:.4g}")
        if self.trajectory is not None:
            bits.append(f"trajectory of {len(self.trajectory.t)} samples")
        where = f" in {self.out}" if self.out else ""
        return f"<exid.StudyResult {self.name!r}: {', '.join(bits)}{where}>"


def read_csv(path: PathLike) -> Dict[str, np.ndarray]:
    """A numeric CSV file (a header line; ``#`` comment lines allowed) read by exid's reader, as
    a dict of column arrays."""
    columns, data = _exid.read_csv(os.fspath(path))
    return {c: data[:, i] for i, c in enumerate(columns)}


def _read_table(path: Path) -> Dict[str, np.ndarray]:
    """A CSV table a study wrote: numeric by exid's reader; one with a text column (the
    parameters' ``name``) by Python's csv module, each column float when every cell is a number,
    else str."""
    try:
        return read_csv(path)
    except _exid.Error:
        pass
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    if not rows:
        return {}
    header, body = rows[0], rows[1:]
    out: Dict[str, np.ndarray] = {}
    for i, name in enumerate(header):
        cells = [r[i] if i < len(r) else "" for r in body]
        try:
            out[name] = np.array([float(c) for c in cells], dtype=float)
        except ValueError:
            out[name] = np.array(cells, dtype=str)
    return out


def read_dataset(path: PathLike) -> Dataset:
    """An experiment.csv (a study's data: ``t``, ``q1..``, ``qd1..``, ``qdd1..``, ``tau1..``,
    optionally ``fx fy fz mx my mz``; SI units, t in s) as a :class:`Dataset`."""
    table = read_csv(path)
    if "t" not in table:
        raise ValueError(f"read_dataset: {os.fspath(path)} has no column 't'; expected t, q1.., qd1.., qdd1..")
    d = _dataset(table)
    assert d is not None
    return d


def _covariance(table: Optional[Dict[str, np.ndarray]], names: List[str]) -> Optional[np.ndarray]:
    """covariance.csv (a ``name`` column, then one column per parameter) as a matrix in the order
    of ``names``; None when the file is absent or names other parameters."""
    if not table or "name" not in table or not names:
        return None
    rows = [str(n) for n in table["name"]]
    if sorted(rows) != sorted(names) or any(n not in table for n in names):
        return None
    order = [rows.index(n) for n in names]
    return np.column_stack([np.asarray(table[n], dtype=float)[order] for n in names])


def _study_args(study: Study, base_dir: Optional[PathLike]) -> Tuple[str, str, str, str]:
    base = os.fspath(base_dir) if base_dir is not None else os.getcwd()
    if isinstance(study, Mapping):
        if "name" not in study:  # a file's study is named after the file; a dict's "study"
            study = {"name": "study", **study}
        return "", _params_text(study), "<dict>", base
    return os.fspath(study), "", "", base


def validate_study(study: Study, base_dir: Optional[PathLike] = None) -> str:
    """Checks a study (a YAML file or a dict) as ``exid validate`` does and returns it resolved
    (every default filled in) as YAML text; a problem raises :class:`exid.Error` naming the key
    (and the line, for a file)."""
    return _exid.resolved_study(*_study_args(study, base_dir))


def _signals(table: Dict[str, np.ndarray], prefix: str) -> Optional[np.ndarray]:
    cols = []
    j = 1
    while f"{prefix}{j}" in table:
        cols.append(table[f"{prefix}{j}"])
        j += 1
    return np.column_stack(cols) if cols else None


def _trajectory(table: Optional[Dict[str, np.ndarray]]) -> Optional[Trajectory]:
    if table is None:
        return None
    return Trajectory(table["t"], _signals(table, "q"), _signals(table, "qd"), _signals(table, "qdd"))


def _dataset(table: Optional[Dict[str, np.ndarray]]) -> Optional[Dataset]:
    if table is None:
        return None
    wrench = None
    if all(c in table for c in ("fx", "fy", "fz", "mx", "my", "mz")):
        wrench = np.column_stack([table[c] for c in ("fx", "fy", "fz", "mx", "my", "mz")])
    return Dataset(
        table["t"],
        _signals(table, "q"),
        _signals(table, "qd"),
        _signals(table, "qdd"),
        _signals(table, "tau"),
        wrench,
    )


def _load(info: Dict[str, Any], folder: Optional[Path]) -> StudyResult:
    summary = json.loads(info["summary"]) if info["summary"] else {}
    status = summary.get("status", "ok" if info["ok"] else "failed")
    result = StudyResult(
        name=summary.get("study", info["name"]),
        status=status,
        message=info["message"] or summary.get("message", ""),
        summary=summary,
        out=folder,
    )
    ident = summary.get("identification") or {}
    for p in ident.get("parameters") or []:
        nan = float("nan")
        result.parameters.append(
            EstimatedParameter(
                p.get("name", ""),
                p.get("expression", ""),
                float(p["value"]) if p.get("value") is not None else nan,
                float(p["std"]) if p.get("std") is not None else nan,
                float(p["nominal"]) if p.get("nominal") is not None else nan,
            )
        )
    if folder is not None:
        for f in sorted(folder.glob("*.csv")):
            result.tables[f.name] = _read_table(f)
    result.covariance = _covariance(result.tables.get("covariance.csv"), result.names)
    result.experiment = _dataset(result.tables.get("experiment.csv"))
    result.trajectory = _trajectory(result.tables.get("trajectory_optimal.csv"))
    result.initial_trajectory = _trajectory(result.tables.get("trajectory_initial.csv"))
    v = summary.get("validation")
    if isinstance(v, dict) and "relative_error" in v:
        metrics = {k: x for k, x in v.items() if k not in ("meta",)}
        rows = result.tables.get("validation.csv")
        result.validation = Validation(
            relative_error=float(v["relative_error"]) if v["relative_error"] is not None else float("nan"),
            metrics=metrics,
            equations=list(v.get("equations") or []),
            t=rows["t"] if rows else None,
            equation=rows["equation"].astype(int) if rows else None,
            measured=rows["measured"] if rows else None,
            predicted=rows["predicted"] if rows else None,
        )
    return result


def run_study(
    study: Study,
    out: Optional[PathLike] = None,
    *,
    stage: Optional[str] = None,
    data: Optional[PathLike] = None,
    base_dir: Optional[PathLike] = None,
    check: bool = True,
) -> StudyResult:
    """Runs a study: a YAML file, or a dict with the same sections (validated the same way:
    JSON is YAML; its relative paths resolve in ``base_dir``, default the current folder; its
    name, when it has none, is "study").

    ``out`` is the output folder (summary.json, report.md, CSV tables), as ``exid run --out``;
    without it the study runs in a temporary folder, read into the result and then removed.
    ``stage`` runs one stage as ``exid excite|simulate|identify`` do: ``"excite"`` (the
    excitation design alone), ``"simulate"`` (the excitation and the experiment) or
    ``"identify"`` (the experiment and the estimator; ``data``, a CSV file or a ROS 2 bag
    folder, replaces the experiment).

    Progress goes to Python's logging: the logger ``"exid"`` gets an INFO record per step of
    each stage (``excitation 40%: ...``; a few a second at most) and one at the start and the
    end (``logging.basicConfig(level=logging.INFO)`` shows them). The result's ``experiment``
    is None for recorded data above 100,000 samples (see :class:`StudyResult`).

    A bad study raises :class:`exid.Error` before anything runs. A study that fails while
    running raises :class:`exid.StudyError` (with ``.result``) unless ``check`` is False, when
    the result comes back with ``status`` "failed". Ctrl-C stops the run (KeyboardInterrupt).
    """
    if stage is not None and stage not in _STAGES:
        raise ValueError(f"run_study: stage {stage!r}; expected one of {', '.join(_STAGES)}")
    path, text, source, base = _study_args(study, base_dir)
    tmp = None
    if out is None:
        tmp = tempfile.mkdtemp(prefix="exid-study-")
        folder = os.path.join(tmp, "out")
    else:
        folder = os.path.abspath(os.fspath(out))
    progress = _log_progress if logger.isEnabledFor(logging.INFO) else None
    label = str(study.get("name", "study")) if isinstance(study, Mapping) else path
    logger.info("study %s: running%s", label, f" (stage {stage})" if stage else "")
    t0 = time.monotonic()
    try:
        info = _exid.run_study(
            path, text, source, base, folder, stage or "", os.fspath(data) if data else "", progress
        )
        written = Path(info["written_to"]) if info["written_to"] else None
        result = _load(info, written)
        if tmp is not None:
            result.out = None
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    logger.info("study %s: %s in %.1f s", result.name, result.status, time.monotonic() - t0)
    if check and not result.ok:
        raise StudyError(f"study '{result.name}' {result.status}: {result.message}", result)
    return result


def _log_progress(stage: str, fraction: float, text: str) -> None:
    """RunOptions::progress, called with the GIL by the compiled module (throttled there)."""
    logger.info("%s %.0f%%%s", stage, 100.0 * fraction, f": {text}" if text else "")
