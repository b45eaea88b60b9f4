"""exid.Robot: parameters, and the physics of the vectorised dynamics on several robots (the
same identities as the C++ tests in tests/dynamics)."""

import numpy as np
import pytest

import exid
from conftest import ROBOTS, smooth_trajectory


def close(a, b, rtol=1e-9, atol=1e-9):
    scale = max(1.0, float(np.max(np.abs(b))))
    np.testing.assert_allclose(a, b, rtol=rtol, atol=atol * scale)


def test_panda_parameters_printable():
    r = exid.Robot("panda")
    assert r.name and r.dof == 7 and len(r.joint_names) == 7
    first = r.base_parameters[:3]
    assert len(first) == 3
    for p in first:
        assert isinstance(p, exid.BaseParameter)
        assert p.name and p.expression and np.isfinite(p.value)
        assert p.name in repr(first)
    assert len(r.standard_parameters) == len(r.standard_names) == len(r.standard_values)
    assert r.standard_names[:10] == ["XX1", "XY1", "XZ1", "YY1", "YZ1", "ZZ1", "MX1", "MY1", "MZ1", "M1"]
    assert 0 < len(r.base_names) < len(r.standard_names)
    # base values are K @ standard values
    close(r.base_matrix @ r.standard_values, r.base_values)
    assert "panda" in repr(r)


def test_regressor_times_parameters_is_rnea(robot, samples):
    q, qd, qdd = samples
    Y = robot.inertial_regressor(q, qd, qdd)
    assert Y.shape == (len(q), robot.dof, 10 * robot.dof)
    tau = robot.rnea(q, qd, qdd)
    assert tau.shape == (len(q), robot.dof)
    close(Y @ robot.inertial_parameters, tau)
    assert np.max(np.abs(tau)) > 1e-3  # not a trivially zero check


def test_rnea_with_own_parameters(robot, samples):
    q, qd, qdd = samples
    pi = robot.inertial_parameters * 1.3
    close(robot.rnea(q, qd, qdd, pi), robot.inertial_regressor(q, qd, qdd) @ pi)


def test_mass_matrix_is_the_acceleration_part_of_rnea(robot, samples):
    q, qd, qdd = samples
    M = robot.mass_matrix(q)
    assert M.shape == (len(q), robot.dof, robot.dof)
    close(M, np.transpose(M, (0, 2, 1)))
    h = robot.rnea(q, qd, np.zeros_like(qdd))
    close(robot.rnea(q, qd, qdd) - h, np.einsum("kij,kj->ki", M, qdd), rtol=1e-8, atol=1e-8)


def test_full_regressor_times_standard_values_is_full_torque(robot_key, samples):
    """With every drive column in the model, regressor @ standard values = the full torque."""
    q, qd, qdd = samples
    cols = {"rotor_inertia": True, "coulomb": True, "viscous": True, "offset": True}
    r = ROBOTS[robot_key](model_params=cols)
    Y = r.regressor(q, qd, qdd)
    assert Y.shape == (len(q), r.dof, len(r.standard_names))
    assert r.standard_names[-4:] == [f"Ia{r.dof}", f"Fc{r.dof}", f"Fv{r.dof}", f"OFF{r.dof}"]
    close(Y @ r.standard_values, r.torque(q, qd, qdd))


def test_base_regressor_times_base_values_is_full_torque(robot, samples):
    q, qd, qdd = samples
    W = robot.base_regressor(q, qd, qdd)
    assert W.shape == (len(q), robot.dof, len(robot.base_names))
    Y = robot.regressor(q, qd, qdd)
    close(W @ robot.base_values, Y @ robot.standard_values, rtol=1e-7, atol=1e-7)
    # ... and for any parameters, through K
    pi = robot.standard_values * np.linspace(0.5, 1.5, len(robot.standard_values))
    close(W @ (robot.base_matrix @ pi), Y @ pi, rtol=1e-7, atol=1e-7)


def test_energy_derivative_is_power(robot):
    """d/dt (kinetic + potential) = tau . qd along a smooth motion (central differences)."""
    h = 1e-5
    t = np.linspace(0.0, 3.0, 31)
    q, qd, qdd = smooth_trajectory(robot, t)
    qp, qdp, _ = smooth_trajectory(robot, t + h)
    qm, qdm, _ = smooth_trajectory(robot, t - h)
    kin, pot = robot.energy_regressor(q, qd)
    assert kin.shape == pot.shape == (len(t), 10 * robot.dof)
    Ep = sum(robot.energy(qp, qdp))
    Em = sum(robot.energy(qm, qdm))
    dE = (Ep - Em) / (2 * h)
    power = np.sum(robot.rnea(q, qd, qdd) * qd, axis=1)
    scale = np.max(np.abs(power))
    assert scale > 1e-3
    np.testing.assert_allclose(dE, power, atol=1e-5 * scale)


def test_wrench_regressor_static_payload():
    """At rest the sensor carries the payload's weight: f = -m g and the moment c x f, both in
    the sensor frame."""
    r = exid.Robot("puma560")
    q, _, _ = r.random_samples(5, seed=3)
    z = np.zeros_like(q)
    m, c = 2.0, np.array([0.01, 0.02, 0.05])
    I = np.diag([0.004, 0.005, 0.003])
    phi = payload_phi(m, c, I)
    A = r.wrench_regressor(q, z, z)
    assert A.shape == (5, 6, 10)
    w = A @ phi
    X = r.body_pose(q, -1)  # sensor frames in the base frame
    for k in range(len(q)):
        R = X[k, :3, :3]
        f = R.T @ (-m * r.gravity)
        close(w[k, :3], f)
        close(w[k, 3:], np.cross(c, f))


def payload_phi(m, c, I_com):
    """phi = M MX MY MZ XX XY XZ YY YZ ZZ about the sensor origin."""
    J = I_com + m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    return np.array([m, *(m * c), J[0, 0], J[0, 1], J[0, 2], J[1, 1], J[1, 2], J[2, 2]])


def test_payload_torques_are_a_heavier_last_body(robot, samples):
    """The payload's torques (payload_torque_regressor @ phi) are what rnea gives when the
    payload is added to the sensor's body."""
    q, qd, qdd = samples
    m, c = 1.5, np.array([0.02, -0.01, 0.04])
    I = np.array([[0.003, 0.0002, 0.0], [0.0002, 0.004, 0.0001], [0.0, 0.0001, 0.002]])
    phi = payload_phi(m, c, I)
    S = robot.sensor_pose  # sensor frame in the body frame
    R, p = S[:3, :3], S[:3, 3]
    cb = R @ c + p
    Jb = R @ I @ R.T + m * (np.dot(cb, cb) * np.eye(3) - np.outer(cb, cb))
    add = np.array([Jb[0, 0], Jb[0, 1], Jb[0, 2], Jb[1, 1], Jb[1, 2], Jb[2, 2], *(m * cb), m])
    pi = robot.inertial_parameters.copy()
    b = robot.sensor_body
    pi[10 * b : 10 * b + 10] += add
    Yp = robot.payload_torque_regressor(q, qd, qdd)
    assert Yp.shape == (len(q), robot.dof, 10)
    close(robot.rnea(q, qd, qdd, pi) - robot.rnea(q, qd, qdd), Yp @ phi, rtol=1e-8, atol=1e-8)


def test_vectorised_equals_one_sample_at_a_time(robot, samples):
    q, qd, qdd = samples
    tau = robot.rnea(q, qd, qdd)
    for k in range(0, len(q), 7):
        one = robot.rnea(q[k], qd[k], qdd[k])
        assert one.shape == (robot.dof,)
        close(one, tau[k], rtol=1e-14, atol=1e-14)
    assert robot.regressor(q[0], qd[0], qdd[0]).shape == (robot.dof, len(robot.standard_names))


def test_layouts_and_dtypes_are_converted():
    r = exid.Robot("puma560")
    q, qd, qdd = r.random_samples(20, seed=2)
    ref = r.rnea(q, qd, qdd)
    close(r.rnea(np.asfortranarray(q), qd.tolist(), qdd.astype(np.longdouble)), ref)
    big = np.zeros((20, 12))
    big[:, ::2] = q
    close(r.rnea(big[:, ::2], qd, qdd), ref)  # a strided view


def test_wrong_shapes_raise_value_error():
    r = exid.Robot("panda")
    q, qd, qdd = r.random_samples(4)
    with pytest.raises(ValueError, match=r"rnea: q has shape \(4, 6\); expected \(N, 7\)"):
        r.rnea(q[:, :6], qd, qdd)
    with pytest.raises(ValueError, match="qd has 3 samples but q has 4"):
        r.rnea(q, qd[:3], qdd)
    with pytest.raises(ValueError, match="qdd"):
        r.regressor(q, qd, np.zeros((4, 7, 1)))
    with pytest.raises(ValueError, match="70 standard inertial parameters"):
        r.rnea(q, qd, qdd, np.ones(3))


def test_unknown_robot_is_an_exid_error():
    with pytest.raises(exid.Error, match="unknown robot 'pnda'.*did you mean 'panda'"):
        exid.Robot("pnda")
    assert issubclass(exid.Error, RuntimeError)
    with pytest.raises(exid.Error, match="no such robot file"):
        exid.Robot("does_not_exist.urdf")
    with pytest.raises(exid.Error, match="model"):
        exid.Robot("panda", model="no_such_model")
    with pytest.raises(exid.Error):
        exid.Robot("panda", model_params={"no_such_key": 1})


def test_plugins_listed():
    names = {p["name"] for p in exid.plugins("robot")}
    assert {"panda", "puma560", "urdf", "dh"} <= names
    with pytest.raises(exid.Error, match="unknown plugin kind"):
        exid.plugins("robots")


_MJCF = """<mujoco model="two"><compiler angle="radian"/><worldbody>
<body name="a" pos="0 0 0.3"><joint name="j1" axis="0 0 1"/>
<inertial pos="0.1 0 0" mass="2" diaginertia="0.01 0.02 0.02"/>
<body name="b" pos="0.4 0 0"><joint name="j2" axis="0 1 0"/>
<inertial pos="0.15 0 0" mass="1" diaginertia="0.005 0.01 0.01"/></body></body>
</worldbody></mujoco>"""

_SDF = """<sdf version="1.9"><model name="two">
<link name="base"/><joint name="fix" type="fixed"><parent>world</parent><child>base</child></joint>
<link name="a"><pose>0 0 0.3 0 0 0</pose><inertial><pose>0.1 0 0 0 0 0</pose><mass>2</mass>
<inertia><ixx>0.01</ixx><ixy>0</ixy><ixz>0</ixz><iyy>0.02</iyy><iyz>0</iyz><izz>0.02</izz></inertia></inertial></link>
<link name="b"><pose relative_to="a">0.4 0 0 0 0 0</pose><inertial><pose>0.15 0 0 0 0 0</pose><mass>1</mass>
<inertia><ixx>0.005</ixx><ixy>0</ixy><ixz>0</ixz><iyy>0.01</iyy><iyz>0</iyz><izz>0.01</izz></inertia></inertial></link>
<joint name="j1" type="continuous"><parent>base</parent><child>a</child><axis><xyz>0 0 1</xyz></axis></joint>
<joint name="j2" type="continuous"><parent>a</parent><child>b</child><axis><xyz>0 1 0</xyz></axis></joint>
</model></sdf>"""


def test_mjcf_and_sdf_files_give_the_same_dynamics(tmp_path):
    (tmp_path / "two.mjcf").write_text(_MJCF)
    (tmp_path / "two.sdf").write_text(_SDF)
    (tmp_path / "mj.xml").write_text(_MJCF)
    (tmp_path / "sd.xml").write_text(_SDF)
    robots = {f: exid.Robot(f, base_dir=tmp_path) for f in ["two.mjcf", "two.sdf", "mj.xml", "sd.xml"]}
    assert robots["two.mjcf"].type == "mjcf" and robots["mj.xml"].type == "mjcf"
    assert robots["two.sdf"].type == "sdf" and robots["sd.xml"].type == "sdf"
    rng = np.random.default_rng(3)
    q, qd, qdd = (rng.uniform(-1, 1, (20, 2)) for _ in range(3))
    ref = robots["two.mjcf"].rnea(q, qd, qdd)
    assert np.max(np.abs(ref)) > 1.0
    for r in robots.values():
        close(r.rnea(q, qd, qdd), ref, rtol=1e-12, atol=1e-12)


def test_floating_base_dynamics():
    """A floating base from Python: the regressor times the description's parameters is the
    Newton-Euler pass, the model's rows are the regressor's, and at rest upright the base rows
    carry the whole weight."""
    r = exid.Robot("humanoid", model="floating_base")
    n = r.dof
    assert r.floating_base
    names = r.floating_parameter_names
    assert len(names) == 10 * (n + 1) and names[9] == "M0"
    rng = np.random.default_rng(3)
    N = 7
    q, qd, qdd = (rng.uniform(-1, 1, (N, n)) for _ in range(3))
    base = np.hstack([rng.uniform(-2, 2, (N, 3)), rng.uniform(-6, 6, (N, 3)),
                      rng.uniform(-15, 15, (N, 3))])
    Y = r.floating_regressor(q, qd, qdd, base)
    assert Y.shape == (N, 6 + n, 10 * (n + 1))
    w = r.floating_inverse_dynamics(q, qd, qdd, base)
    assert w.shape == (N, 6 + n)
    close(Y @ r.floating_parameter_values, w, rtol=1e-11, atol=1e-9)
    pi = r.floating_parameter_values * 1.5
    close(r.floating_inverse_dynamics(q, qd, qdd, base, pi), 1.5 * w, rtol=1e-11, atol=1e-9)
    rows = r.regressor(q, qd, qdd, base=base)
    close(rows, Y, rtol=1e-12, atol=1e-12)
    # at rest, upright in gravity: f = a - g = (0, 0, 9.81); the base rows hold m_total f
    rest = np.zeros(n)
    up = np.array([0, 0, 0, 0, 0, 0, 0, 0, 9.81])
    w0 = r.floating_inverse_dynamics(rest, rest, rest, up)
    m_total = sum(r.floating_parameter_values[10 * b + 9] for b in range(n + 1))
    close(w0[:3], np.array([0, 0, m_total * 9.81]), rtol=1e-12, atol=1e-9)


def test_floating_base_refusals():
    with pytest.raises(ValueError, match="model='floating_base'"):
        exid.Robot("humanoid")
    r = exid.Robot("humanoid", model="floating_base")
    q = np.zeros(r.dof)
    with pytest.raises(ValueError, match="floating_regressor"):
        r.rnea(q, q, q)
    with pytest.raises(ValueError, match="give its motion base"):
        r.regressor(q, q, q)
    with pytest.raises(ValueError, match=r"expected \(N, 9\)"):
        r.floating_regressor(q, q, q, np.zeros(6))
    with pytest.raises(ValueError, match="fixed base"):
        exid.Robot("panda").floating_regressor(np.zeros(7), np.zeros(7), np.zeros(7), np.zeros(9))
    assert not exid.Robot("panda").floating_base
