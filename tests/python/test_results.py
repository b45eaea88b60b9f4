"""What a study gives Python beyond its parameters: the estimate's covariance and correlation,
every table it wrote, the experiment's samples (and when they are not kept), its progress through
Python's logging, and how it shows itself in Jupyter."""

import logging
import re

import numpy as np
import pytest

import exid

from test_study import SMALL


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    return exid.run_study(SMALL, tmp_path_factory.mktemp("results") / "out")


def test_covariance_is_the_estimators(small):
    n = len(small.parameters)
    cov = small.covariance
    assert cov is not None and cov.shape == (n, n)
    np.testing.assert_allclose(cov, cov.T, rtol=0, atol=0)
    # the covariance the estimator wrote (covariance.csv), in the order of res.names, gives the
    # standard deviations it reported (parameters.csv, summary.json)
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), small.std, rtol=1e-12)
    corr = small.correlation
    np.testing.assert_allclose(np.diag(corr), 1.0, rtol=0, atol=0)
    assert np.all(np.abs(corr) <= 1 + 1e-12)


def test_covariance_survives_a_temporary_folder():
    res = exid.run_study(SMALL)
    assert res.out is None and res.covariance is not None
    np.testing.assert_allclose(np.sqrt(np.diag(res.covariance)), res.std, rtol=1e-12)


def test_every_table_is_there(small):
    files = sorted(p.name for p in small.out.glob("*.csv"))
    assert files == sorted(small.tables) and "parameters.csv" in files and "covariance.csv" in files
    p = small.tables["parameters.csv"]
    assert list(p["name"]) == small.names  # a text column, as str
    np.testing.assert_array_equal(p["value"], small.values)
    np.testing.assert_array_equal(p["std"], small.std)
    c = small.tables["covariance.csv"]
    assert list(c["name"]) == small.names and set(small.names) <= set(c)
    pd = pytest.importorskip("pandas")
    df = pd.DataFrame(small.tables["parameters.csv"]).set_index("name")
    assert df.loc[small.names[0], "value"] == small.values[0]


def test_experiment_and_read_dataset(small, tmp_path):
    e = small.experiment
    assert e is not None and e.q.shape == (len(e.t), 2) and e.tau.shape == e.q.shape
    again = exid.read_dataset(small.out / "experiment.csv")
    np.testing.assert_array_equal(again.q, e.q)
    np.testing.assert_array_equal(again.tau, e.tau)
    (tmp_path / "x.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="no column 't'"):
        exid.read_dataset(tmp_path / "x.csv")


def test_progress_goes_to_logging(caplog):
    caplog.set_level(logging.INFO, logger="exid")
    exid.run_study(SMALL)
    records = [r for r in caplog.records if r.name == "exid"]
    steps = [r.getMessage() for r in records]
    assert all(r.levelno == logging.INFO for r in records)
    assert steps[0] == "study py_small: running"
    assert any(re.match(r"experiment \d+%: ", s) for s in steps), steps
    assert any(s.startswith("identification 100%") for s in steps), steps
    assert "study py_small: ok" in steps[-1]


def test_no_progress_records_below_info(caplog):
    caplog.set_level(logging.WARNING, logger="exid")
    exid.run_study(SMALL)
    assert not [r for r in caplog.records if r.name == "exid"]


def test_a_raising_progress_callback_does_not_stop_the_study(monkeypatch):
    # the compiled module reports the callback's exception as unraisable and goes on
    seen = []
    monkeypatch.setattr("sys.unraisablehook", lambda u: seen.append(u.exc_type))

    def boom(stage, fraction, text):
        raise RuntimeError("callback failed")

    monkeypatch.setattr("exid._study._log_progress", boom)
    monkeypatch.setattr("exid._study.logger.isEnabledFor", lambda level: True)
    res = exid.run_study(SMALL)
    assert res.ok and seen and all(t is RuntimeError for t in seen)


def test_repr_html_and_markdown(small):
    pytest.importorskip("matplotlib")
    h = small._repr_html_()
    assert "<table" in h and "<img" in h and "data:image/png;base64," in h
    assert small.names[0] in h and "validation relative error" in h
    md = small._repr_markdown_()
    assert md.startswith("**exid study py_small**") and "| status | ok |" in md


def test_data_path():
    study = exid.data_path("examples/real/tx40_wls.yaml")
    assert study.is_file()
    assert (exid.data_path() / "robots" / "tx40" / "tx40_exid.xml").is_file()
    with pytest.raises(FileNotFoundError, match="no_such_file.yaml"):
        exid.data_path("examples/no_such_file.yaml")
