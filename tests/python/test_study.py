"""exid.run_study: files and dicts, one stage, results as Python objects, errors."""

import numpy as np
import pytest

import exid

# A small study as a dict: the two-link arm, a simulated experiment, batch least squares, a
# validation experiment; no plots (fast).
SMALL = {
    "name": "py_small",
    "seed": 1,
    "robot": {"type": "planar2r"},
    "model": {
        "type": "differential",
        "params": {"rotor_inertia": False, "coulomb": False, "viscous": False},
    },
    "experiment": {
        "type": "simulate",
        "params": {"duration_s": 4, "sample_period_s": 0.01, "noise_tau_Nm": 0.01, "drive_terms": False},
    },
    "estimator": {"type": "batch_ls"},
    "validation": {
        "type": "simulate",
        "params": {"duration_s": 3, "sample_period_s": 0.01, "noise_tau_Nm": 0.01, "drive_terms": False},
    },
    "report": {"type": "standard", "params": {"plots": False}},
}

EXCITE = {
    **SMALL,
    "name": "py_excite",
    "excitation": {
        "trajectory": {"type": "fourier", "params": {"period_s": 4, "harmonics": 3, "sample_period_s": 0.05}},
        "criterion": {"type": "cond"},
        "optimizer": {"type": "nlopt", "params": {"max_evaluations": 100}},
    },
    "experiment": {
        "type": "simulate",
        "params": {"duration_s": 3.9, "sample_period_s": 0.01, "noise_tau_Nm": 0.01, "drive_terms": False},
    },
}


def test_dict_study(tmp_path):
    res = exid.run_study(SMALL, tmp_path / "out")
    assert res.ok and res.status == "ok" and res.name == "py_small"
    assert res.out == tmp_path / "out" and (res.out / "summary.json").is_file()
    assert res.summary["status"] == "ok"
    n = len(res.parameters)
    assert n == res.summary["model"]["n_base"] > 0
    assert res.values.shape == res.std.shape == (n,)
    assert np.all(res.std > 0) and np.all(np.isfinite(res.values))
    # a simulated study knows the truth: the estimate is within a few sigma of it
    assert np.all(np.abs(res.values - res.nominal) < 6 * res.std + 1e-9)
    v = res.validation
    assert v is not None and 0 <= v.relative_error < 0.05
    assert len(v.equations) == 2 and v.measured.shape == v.predicted.shape == v.t.shape
    t0, m0, p0 = v.of_equation(0)
    assert len(t0) == len(v.t) // 2
    assert np.sqrt(np.mean((m0 - p0) ** 2)) < 0.1
    e = res.experiment
    assert e.q.shape == e.qd.shape == e.qdd.shape == e.tau.shape == (len(e.t), 2)
    assert res.trajectory is None


def test_file_study_in_a_temporary_folder(source_dir, tmp_path):
    study = tmp_path / "s.yaml"
    study.write_text(
        "name: from_file\nrobot: {type: planar2r}\n"
        "model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: false}}\n"
        "experiment: {type: simulate, params: {duration_s: 3, drive_terms: false, noise_tau_Nm: 0.01}}\n"
        "estimator: {type: rls}\n"
        "report: {type: standard, params: {plots: false}}\n"
    )
    res = exid.run_study(study)
    assert res.ok and res.out is None and res.name == "from_file"
    assert len(res.parameters) > 0 and np.all(res.std > 0)
    assert "estimate_history.csv" in res.tables  # recursive estimator: its history
    assert "identification" in res.summary


def test_excitation_stage_alone(tmp_path):
    res = exid.run_study(EXCITE, tmp_path / "x", stage="excite")
    assert res.ok and res.parameters == [] and res.experiment is None
    tr, t0 = res.trajectory, res.initial_trajectory
    assert tr is not None and t0 is not None
    assert tr.q.shape == tr.qd.shape == tr.qdd.shape == (len(tr.t), 2) and len(tr.t) > 10
    x = res.summary["excitation"]
    assert x["criterion_final"] <= x["criterion_initial"]


def test_simulate_then_identify_from_the_csv(tmp_path):
    sim = exid.run_study(SMALL, tmp_path / "sim", stage="simulate")
    assert sim.ok and sim.parameters == [] and sim.experiment is not None
    csv = tmp_path / "sim" / "experiment.csv"
    ident = exid.run_study(SMALL, tmp_path / "id", stage="identify", data=csv)
    assert ident.ok and len(ident.parameters) > 0 and ident.validation is None
    assert ident.summary["experiment"]["type"] == "csv"
    whole = exid.run_study(SMALL)
    np.testing.assert_allclose(ident.values, whole.values, rtol=1e-6, atol=1e-8)


def test_shipped_example_study(source_dir, tmp_path):
    """The default study, as shipped (examples/default.yaml: PUMA 560, simulated, plots)."""
    res = exid.run_study(source_dir / "examples/default.yaml", tmp_path / "d")
    assert res.ok and len(res.parameters) == res.summary["model"]["n_base"]
    assert res.validation.relative_error < 0.05


def test_bad_study_key_is_an_exid_error():
    bad = {**SMALL, "estimator": {"type": "batch_ls", "params": {"forgetting_factor": 0.9}}}
    with pytest.raises(exid.Error, match="estimator.params.forgetting_factor"):
        exid.run_study(bad)
    with pytest.raises(exid.Error, match="unknown estimator 'bach_ls'.*did you mean 'batch_ls'"):
        exid.run_study({**SMALL, "estimator": {"type": "bach_ls"}})
    with pytest.raises(exid.Error, match="no_such_section"):
        exid.validate_study({**SMALL, "no_such_section": 1})
    with pytest.raises(exid.Error, match="no excitation section"):
        exid.run_study(SMALL, stage="excite")
    with pytest.raises(ValueError, match="stage"):
        exid.run_study(SMALL, stage="fly")


def test_bad_yaml_file_names_the_line(tmp_path):
    f = tmp_path / "bad.yaml"
    f.write_text("robot: {type: planar2r}\nestimator:\n  type: batch_ls\n  params: {cutoff: 3}\n")
    with pytest.raises(exid.Error, match=r"bad.yaml:\d+: estimator.params.cutoff"):
        exid.validate_study(f)


def test_a_failing_study_raises_study_error(tmp_path):
    failing = {**EXCITE, "experiment": {"type": "simulate", "params": {"duration_s": 30}}}
    with pytest.raises(exid.StudyError, match="experiment") as info:
        exid.run_study(failing, tmp_path / "f")
    r = info.value.result
    assert r.status == "failed" and r.trajectory is not None  # what the excitation stage wrote
    r2 = exid.run_study(failing, check=False)
    assert not r2.ok and "experiment" in r2.message


def test_validate_study_resolves_defaults():
    text = exid.validate_study(SMALL)
    assert "batch_ls" in text and "planar2r" in text


def test_ctrl_c_stops_a_run(source_dir, tmp_path):
    """SIGINT during a long run (an excitation of 2000 criterion evaluations) stops it: the run
    is recorded as cancelled and KeyboardInterrupt is raised."""
    import os
    import signal
    import subprocess
    import sys
    import time

    script = (
        "import exid, sys\n"
        "print('running', flush=True)\n"
        "try:\n"
        f"    exid.run_study({str(source_dir / 'examples/bench/puma560_fourier.yaml')!r}, {str(tmp_path / 'o')!r})\n"
        "    print('finished')\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted')\n"
    )
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, env=os.environ.copy())
    assert p.stdout.readline().strip() == "running"
    time.sleep(0.5)
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    out, _ = p.communicate(timeout=60)
    assert out.strip() == "interrupted"
    assert time.monotonic() - t0 < 10
    summary = tmp_path / "o.failed" / "summary.json"
    if not summary.exists():
        summary = tmp_path / "o" / "summary.json"
    import json

    assert json.loads(summary.read_text())["status"] == "cancelled"
