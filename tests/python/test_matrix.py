"""exid.run_matrix and exid.read_matrix: a matrix's SQLite results as a pandas DataFrame."""

import numpy as np
import pytest

import exid

MATRIX = """\
name: py_matrix
study:
  robot: {type: planar2r}
  model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: false}}
  experiment: {type: simulate, params: {duration_s: 3, sample_period_s: 0.01, noise_tau_Nm: 0.01, drive_terms: false}}
  estimator: {type: batch_ls}
axes:
  estimator: [{type: batch_ls}, {type: rls}]
  seed: [1, 2]
"""


@pytest.fixture(scope="module")
def matrix_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("matrix")
    (d / "m.yaml").write_text(MATRIX)
    s = exid.run_matrix(d / "m.yaml", d / "out", jobs=2)
    assert s["total"] == 4 and s["ok"] == 4 and s["failed"] == 0
    assert s["database"].endswith("results.sqlite")
    return d / "out"


def test_read_matrix(matrix_dir):
    df = exid.read_matrix(matrix_dir)
    assert len(df) == 4
    assert set(df["status"]) == {"ok"}
    assert set(df["matrix"]) == {"py_matrix"}
    assert sorted(set(df["estimator"])) == ["batch_ls", "rls"]
    assert sorted(set(df["seed"])) == ["1", "2"]
    err = df["identification.param_rel_err"]
    assert err.dtype == np.float64 and np.all(err < 0.05)
    # the same database file, and the summaries
    df2 = exid.read_matrix(matrix_dir / "results.sqlite", metrics=False, summary=True)
    assert len(df2) == 4 and "identification.param_rel_err" not in df2.columns
    assert all(s["status"] == "ok" for s in df2["summary"])


def test_matrix_resume_skips_finished_cells(matrix_dir):
    s = exid.run_matrix(matrix_dir.parent / "m.yaml", matrix_dir)
    assert s["skipped"] == 4 and s["ok"] == 0
    assert len(exid.read_matrix(matrix_dir)) == 4


def test_read_matrix_errors(tmp_path):
    with pytest.raises(exid.Error, match="no matrix database"):
        exid.read_matrix(tmp_path)
    (tmp_path / "results.sqlite").write_text("not sqlite")
    with pytest.raises(exid.Error, match="not a matrix database"):
        exid.read_matrix(tmp_path)
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nstudy: {robot: {type: planar2r}}\naxes: {estimator: [{type: bach_ls}]}\n")
    with pytest.raises(exid.Error, match="bach_ls"):
        exid.run_matrix(bad, tmp_path / "o")
