"""exid.Robot: a robot description, its parameters and its dynamics on arrays of samples."""

from __future__ import annotations

import json
import os
from typing import Any, List, Mapping, NamedTuple, Optional, Tuple, Union

import numpy as np

from . import _exid

PathLike = Union[str, "os.PathLike[str]"]


class Parameter(NamedTuple):
    """A standard parameter: its name (``XX1`` ... ``M7``, then drive columns ``Ia1``, ``Fc1``,
    ``Fv1``, ``OFF1`` when the model identifies them) and its value in the robot description."""

    name: str
    value: float


class BaseParameter(NamedTuple):
    """A base (identifiable) parameter: its name (``ZZ1R`` when standard parameters are
    regrouped into it), its expression in standard parameters and its nominal value."""

    name: str
    expression: str
    value: float


def _params_text(params: Optional[Mapping[str, Any]]) -> str:
    """A params mapping as JSON text (JSON is YAML): exid resolves and validates it."""
    if params is None:
        return "{}"
    if not isinstance(params, Mapping):
        raise TypeError(f"params must be a dict (got {type(params).__name__})")

    def default(o: Any) -> Any:
        if hasattr(o, "tolist"):  # numpy arrays and scalars
            return o.tolist()
        if isinstance(o, os.PathLike):
            return os.fspath(o)
        raise TypeError(f"params: {o!r} ({type(o).__name__}) cannot be written as YAML")

    return json.dumps(dict(params), default=default)


_FILE_TYPES = {
    ".urdf": "urdf",
    ".yaml": "dh",
    ".yml": "dh",
    ".sdf": "sdf",
    ".mjcf": "mjcf",
    ".xml": None,  # by its root element
}


def _xml_root(path: str) -> str:
    """The root element's name of an XML file ("" when it is not XML)."""
    import xml.etree.ElementTree as ET

    try:
        for _, elem in ET.iterparse(path, events=("start",)):
            return elem.tag
    except ET.ParseError:
        pass
    return ""


class Robot:
    """A robot: a robot plugin by name (``"panda"``, ``"puma560"``, ...), a robot file (``.urdf``,
    ``.sdf``, ``.mjcf``, ``.xml`` by its root element: ``<mujoco>`` MJCF, ``<sdf>`` SDF, else
    URDF; DH ``.yaml``), or a study's robot section (``{"type": "urdf", "params": {...}}``).

    ``params`` are the robot plugin's parameters (``exid plugins info urdf``); for a file they
    are added to ``file``. ``model`` and ``model_params`` choose the observation model whose
    columns define the standard and base parameters (default: ``differential`` with its
    defaults: rigid-body parameters, rotor inertia, Coulomb and viscous friction). Relative
    paths resolve in ``base_dir`` (default: the current folder).

    Every method on samples takes float64 arrays shaped (N, dof) (or (dof,) for one sample) in
    the robot's measured coordinates (its joint coordinates unless it has a transmission, as in
    studies and ``exid eval``) and returns new arrays with N first. The loops run in C++ without
    the GIL; C-ordered float64 input is read in place.
    """

    def __init__(
        self,
        robot: Union[PathLike, Mapping[str, Any]],
        params: Optional[Mapping[str, Any]] = None,
        *,
        model: str = "differential",
        model_params: Optional[Mapping[str, Any]] = None,
        base_dir: Optional[PathLike] = None,
        seed: int = 1,
    ) -> None:
        params = dict(params or {})
        base = os.fspath(base_dir) if base_dir is not None else os.getcwd()
        if isinstance(robot, Mapping):
            if "type" not in robot:
                raise ValueError("Robot: a robot section needs a 'type' (e.g. {'type': 'panda'})")
            kind = str(robot["type"])
            params = {**dict(robot.get("params") or {}), **params}
        else:
            text = os.fspath(robot)
            ext = os.path.splitext(text)[1].lower()
            if ext in _FILE_TYPES:
                path = os.path.join(base, text)
                if not os.path.exists(path):
                    raise _exid.Error(f"{text}: no such robot file")
                kind = _FILE_TYPES[ext]
                if kind is None:
                    root = _xml_root(path)
                    kind = "mjcf" if root == "mujoco" else "sdf" if root == "sdf" else "urdf"
                params = {"file": os.path.abspath(path), **params}
            else:
                kind = text
        self._r = _exid.Robot(
            kind, _params_text(params), model, _params_text(model_params), base, int(seed)
        )

    def __repr__(self) -> str:
        return (
            f"<exid.Robot {self.name!r} ({self.type}): {self.dof} joints, model {self.model}, "
            f"{len(self.standard_names)} standard / {len(self.base_names)} base parameters>"
        )

    # ------------------------------------------------------------------ description
    @property
    def name(self) -> str:
        """The robot's name."""
        return self._r.name

    @property
    def type(self) -> str:
        """The robot plugin that built it (``urdf``, ``sdf``, ``mjcf`` and ``dh`` for files)."""
        return self._r.type

    @property
    def model(self) -> str:
        """The observation model bound to the robot."""
        return self._r.model

    @property
    def dof(self) -> int:
        """Number of joints."""
        return self._r.dof

    @property
    def joint_names(self) -> List[str]:
        """The joints' names, in body order."""
        return self._r.joint_names

    @property
    def link_names(self) -> List[str]:
        """The moving bodies' (links') names."""
        return self._r.link_names

    @property
    def joint_types(self) -> List[str]:
        """``revolute`` or ``prismatic`` per joint."""
        return self._r.joint_types

    @property
    def parents(self) -> List[int]:
        """Parent body of each body (-1: the fixed base)."""
        return self._r.parents

    @property
    def limits(self) -> dict:
        """Joint limits (joint coordinates) as arrays: q_min, q_max, qd_max, qdd_max, tau_max (inf
        where unknown)."""
        return self._r.limits

    @property
    def gravity(self) -> np.ndarray:
        """Gravity in the base frame [m/s^2]."""
        return self._r.gravity

    @property
    def transmission(self) -> Optional[np.ndarray]:
        """T in q = T qm + q0 (joint from measured coordinates), or None (identity)."""
        return self._r.transmission

    @property
    def notes(self) -> List[str]:
        """Facts the description states of itself (known defects of published data, ...)."""
        return self._r.notes

    @property
    def warnings(self) -> List[str]:
        """What loading found and the user may act on (physically impossible inertia, ...)."""
        return self._r.warnings

    @property
    def sensor_body(self) -> int:
        """The body (0-based) the wrist sensor and payload are attached to."""
        return self._r.sensor_body

    @property
    def sensor_pose(self) -> np.ndarray:
        """The sensor frame in that body's frame, a 4 x 4 homogeneous transform."""
        return self._r.sensor_pose

    # ------------------------------------------------------------------ parameters
    @property
    def inertial_parameter_names(self) -> List[str]:
        """The 10 standard inertial parameters per body: XX XY XZ YY YZ ZZ MX MY MZ M."""
        return self._r.inertial_parameter_names

    @property
    def inertial_parameters(self) -> np.ndarray:
        """Their values in the description (10 dof), the order of :meth:`inertial_regressor`."""
        return self._r.inertial_parameter_values

    @property
    def standard_names(self) -> List[str]:
        """The model's full (standard) parameters: inertial, then the drive columns."""
        return self._r.standard_names

    @property
    def standard_values(self) -> np.ndarray:
        """Their nominal values, the column order of :meth:`regressor`."""
        return self._r.standard_values

    @property
    def standard_parameters(self) -> List[Parameter]:
        """The standard parameters with their nominal values."""
        return [Parameter(n, float(v)) for n, v in zip(self.standard_names, self.standard_values)]

    @property
    def base_names(self) -> List[str]:
        """The base parameters' names (``ZZ1R`` when regrouped, else the standard name)."""
        return self._r.base_names

    @property
    def base_expressions(self) -> List[str]:
        """Each base parameter in standard parameters, e.g. ``ZZ1 + YY2 + 0.186*M3``."""
        return self._r.base_expressions

    @property
    def base_values(self) -> np.ndarray:
        """The base parameters' nominal values (base_matrix @ standard_values)."""
        return self._r.base_values

    @property
    def base_matrix(self) -> np.ndarray:
        """K (base x standard): base parameters = K @ standard parameters."""
        return self._r.base_matrix

    @property
    def base_parameters(self) -> List[BaseParameter]:
        """The base parameters with their expressions and nominal values."""
        return [
            BaseParameter(n, e, float(v))
            for n, e, v in zip(self.base_names, self.base_expressions, self.base_values)
        ]

    # ------------------------------------------------------------------ samples
    def random_samples(self, count: int, seed: int = 1) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``count`` random samples (q, qd, qdd), each (count, dof), within the robot's limits
        (those the model draws to find the base parameters)."""
        return self._r.random_samples(count, seed)

    # ------------------------------------------------------------------ dynamics
    def rnea(self, q, qd, qdd, parameters: Optional[np.ndarray] = None) -> np.ndarray:
        """Rigid-body torques (N, dof) by recursive Newton-Euler, with the description's inertial
        parameters or ``parameters`` (10 dof, :attr:`inertial_parameter_names` order). No drive
        terms; measured coordinates (T^T tau with a transmission)."""
        return self._r.rnea(q, qd, qdd, parameters)

    def torque(self, q, qd, qdd) -> np.ndarray:
        """The full torque (N, dof): rigid bodies plus every drive term the description has
        (rotor inertia, Coulomb and viscous friction, offset), as ``exid eval --what torque``."""
        return self._r.torque(q, qd, qdd)

    def inertial_regressor(self, q, qd, qdd) -> np.ndarray:
        """Y (N, dof, 10 dof) with rnea(q, qd, qdd) = Y @ inertial_parameters."""
        return self._r.inertial_regressor(q, qd, qdd)

    def regressor(
        self, q, qd, qdd, t: Optional[np.ndarray] = None, base: Optional[np.ndarray] = None
    ) -> np.ndarray:
        """The model's rows in standard columns (:attr:`standard_names`): (N, rows per sample, p)
        for a per-sample model (differential: one row per joint, Y @ standard_values is the
        torque the model predicts); stacked (rows, p) for a model over windows (integral),
        which needs the sample times ``t``. A floating base (model ``floating_base``) needs its
        motion ``base`` (N, 9): omega, alpha, f = a - g in the base frame."""
        return self._r.regressor(q, qd, qdd, t, base)

    def base_regressor(
        self, q, qd, qdd, t: Optional[np.ndarray] = None, base: Optional[np.ndarray] = None
    ) -> np.ndarray:
        """The same rows in base columns (:attr:`base_names`): W @ base_values = Y @
        standard_values."""
        return self._r.base_regressor(q, qd, qdd, t, base)

    # ------------------------------------------------------------------ floating base
    @property
    def floating_base(self) -> bool:
        """Whether the robot's root body moves freely (docs/robots.md, "Floating base")."""
        return self._r.floating_base

    @property
    def floating_parameter_names(self) -> List[str]:
        """A floating base's parameters: the base link's ten (XX0 ... M0), then each body's;
        empty for a fixed base."""
        return self._r.floating_parameter_names

    @property
    def floating_parameter_values(self) -> Optional[np.ndarray]:
        """Their values in the description (None for a fixed base)."""
        return self._r.floating_parameter_values

    def floating_regressor(self, q, qd, qdd, base) -> np.ndarray:
        """Y (N, 6 + dof, 10 (dof + 1)) of a floating base: the six base rows (the total wrench
        on the robot about the base origin, base frame) and the joint rows, given the base
        motion ``base`` (N, 9): omega, alpha, f = a - g in the base frame. Y @
        floating_parameter_values = [0; tau] + the contact wrenches' contributions."""
        return self._r.floating_regressor(q, qd, qdd, base)

    def floating_inverse_dynamics(
        self, q, qd, qdd, base, parameters: Optional[np.ndarray] = None
    ) -> np.ndarray:
        """[w_base; tau] (N, 6 + dof) by a Newton-Euler pass, with the description's floating
        parameters or ``parameters`` (10 (dof + 1))."""
        return self._r.floating_inverse_dynamics(q, qd, qdd, base, parameters)

    def energy_regressor(self, q, qd) -> Tuple[np.ndarray, np.ndarray]:
        """(kinetic, potential), each (N, 10 dof): T = kinetic @ pi, U = potential @ pi with pi
        the inertial parameters; d(T + U)/dt = rnea . qd."""
        return self._r.energy_regressor(q, qd)

    def energy(self, q, qd) -> Tuple[np.ndarray, np.ndarray]:
        """Kinetic and potential energy (N,) each, with the description's parameters."""
        k, u = self._r.energy_regressor(q, qd)
        pi = self.inertial_parameters
        return k @ pi, u @ pi

    def wrench_regressor(self, q, qd, qdd) -> np.ndarray:
        """A (N, 6, 10): the wrench (fx fy fz mx my mz, sensor frame) the robot exerts on a
        payload phi = (M MX MY MZ XX XY XZ YY YZ ZZ) about the sensor origin is A @ phi."""
        return self._r.wrench_regressor(q, qd, qdd)

    def payload_torque_regressor(self, q, qd, qdd) -> np.ndarray:
        """Yp (N, dof, 10): the payload's joint torques are Yp @ phi."""
        return self._r.payload_torque_regressor(q, qd, qdd)

    def mass_matrix(self, q, parameters: Optional[np.ndarray] = None) -> np.ndarray:
        """The mass matrix (N, dof, dof) in measured coordinates (T^T M T)."""
        return self._r.mass_matrix(q, parameters)

    def body_pose(self, q, body: int) -> np.ndarray:
        """The pose of body ``body`` (0-based; -1: the sensor frame) in the base frame, as
        (N, 4, 4) homogeneous transforms."""
        return self._r.body_pose(q, body)
