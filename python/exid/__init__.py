"""exid: experimental identification of robot and payload dynamics, from Python.

The same robots, plugins and studies as the ``exid`` program, on numpy arrays::

    import exid
    r = exid.Robot("panda")                    # a robot plugin, a .urdf or a DH .yaml file
    print(r.base_parameters[:3])               # names, expressions, nominal values
    q, qd, qdd = r.random_samples(1000)        # (N, dof) arrays within the limits
    tau = r.rnea(q, qd, qdd)                   # (N, dof) rigid-body torques
    Y = r.regressor(q, qd, qdd)                # (N, dof, p): tau = Y @ r.standard_values

    res = exid.run_study(exid.data_path("examples/default.yaml"))  # or a dict
    res.parameters, res.covariance, res.correlation, res.validation, res.tables
    df = exid.read_matrix("out/ci_matrix")          # a matrix's results as a pandas DataFrame

Errors of exid (a bad study key, an unknown robot, a singular problem) raise :class:`exid.Error`
(a RuntimeError) with exid's message; a wrong array shape raises ValueError. See docs/python.md.
"""

from ._data import data_path
from ._exid import Error, __version__, git_commit, set_log_level
from ._exid import add_plugin_path as _add_plugin_path
from ._exid import plugin_search_paths, refused_libraries
from ._exid import plugins as _plugins
from ._matrix import read_matrix, run_matrix
from ._robot import BaseParameter, Parameter, Robot
from ._study import (
    Dataset,
    EstimatedParameter,
    StudyError,
    StudyResult,
    Trajectory,
    Validation,
    read_csv,
    read_dataset,
    run_study,
    validate_study,
)

# Shown as exid.Error and exid.StudyError in tracebacks.
Error.__module__ = __name__
StudyError.__module__ = __name__

__all__ = [
    "BaseParameter",
    "Dataset",
    "Error",
    "EstimatedParameter",
    "Parameter",
    "Robot",
    "StudyError",
    "StudyResult",
    "Trajectory",
    "Validation",
    "__version__",
    "add_plugin_path",
    "data_path",
    "git_commit",
    "plugin_search_paths",
    "plugins",
    "read_csv",
    "read_dataset",
    "read_matrix",
    "refused_libraries",
    "run_matrix",
    "run_study",
    "set_log_level",
    "validate_study",
]


def plugins(kind: str = "") -> list:
    """The plugins found, each a dict (kind, name, version, doc, library, params).

    ``kind`` restricts the list to one kind: robot, model, criterion, trajectory, optimizer,
    experiment or estimator (an unknown kind raises :class:`exid.Error`).
    """
    return _plugins(kind)


def add_plugin_path(directory) -> None:
    """Searches ``directory`` for plugin libraries first (as ``exid --plugin-path``)."""
    import os

    _add_plugin_path(os.fspath(directory))
