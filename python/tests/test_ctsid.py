"""The Python package against the command line and against truth.

Needs the package installed (`pip install ./python`) and, for the comparisons with the command
line, its binary: `CTSID_BIN`, else `target/release/ctsid` of this repository (built by `cargo
test --release`); without it those tests skip with a notice.
"""

import copy
import json
import logging
import os
import pickle
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import ctsid

ROOT = Path(__file__).resolve().parents[2]
TAU = 0.003


def cli():
    exe = os.environ.get("CTSID_BIN", str(ROOT / "target" / "release" / "ctsid"))
    if not Path(exe).is_file():
        pytest.skip(f"NOTICE: no ctsid binary at {exe} (build it with cargo build --release)")
    return exe


def run_cli(*args):
    out = subprocess.run([cli(), *args], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout


def same_model(a, b):
    """The same model file but for its `training` section, which records the fit's timings."""
    strip = lambda m: {k: v for k, v in json.loads(m.to_json()).items() if k != "training"}
    return strip(a) == strip(b)


@pytest.fixture(scope="module")
def throttle(tmp_path_factory):
    """Twelve runs of the paper's throttle at 3 % noise, written as the CLI reads it."""
    path = tmp_path_factory.mktemp("throttle") / "throttle.csv"
    ctsid.throttle_dataset(str(path), runs=12, samples=1000, tau=TAU, noise=0.03, seed=7)
    return path


SETTINGS = dict(train="0-7", validation="8-9", test="10-11", degree=2, order=3)


@pytest.fixture(scope="module")
def fitted(throttle):
    data = pd.read_csv(throttle)
    model = ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run", **SETTINGS)
    return data, model


def test_python_and_cli_identify_the_same_model(throttle, fitted, tmp_path):
    _, model = fitted
    out = tmp_path / "cli.json"
    run_cli(
        "identify", str(throttle), "--output", "y", "--input", "u", "--run-column", "run",
        "--tau", str(TAU), "--train", "0-7", "--validation", "8-9", "--test", "10-11",
        "--degree", "2", "--order", "3", "--quiet", "-o", str(out),
    )
    from_cli = ctsid.load(str(out))
    assert from_cli.equations() == model.equations()
    a = [(c["term"], c["coefficient"]) for c in model.coefficients()]
    b = [(c["term"], c["coefficient"]) for c in from_cli.coefficients()]
    assert a == b


def test_identify_reports_its_fit_and_simulates_every_run(fitted):
    data, model = fitted
    assert model.orders == [3]
    nrmse = model.summary["test_nrmse"][0]
    assert 0 < nrmse < 1, model.summary
    assert all(c["std_error"] is not None for c in model.coefficients())
    sims = model.simulate(data, run_column="run")
    assert set(sims) == {str(r) for r in range(12)}
    assert sims["10"].shape == (1000, 1)
    # The model file carries what `ctsid identify -o` records: settings and training runs.
    training = json.loads(model.to_json())["training"]
    assert training["settings"]["train"] == [str(r) for r in range(8)]
    assert training["settings"]["degree"] == 2


def test_a_model_round_trips_between_python_and_the_cli(throttle, fitted, tmp_path):
    data, model = fitted
    path = tmp_path / "py.json"
    model.save(str(path))
    # The CLI reads what Python wrote and scores it as Python does.
    printed = run_cli("simulate", str(path), str(throttle), "--run-column", "run", "--tau", str(TAU))
    rows = {l.split()[0]: float(l.split()[2]) for l in printed.splitlines()[1:] if l.split()[1] == "y"}
    scores = {s["run"]: s["rms"] for s in model.score(data, run_column="run")}
    for run, rms in scores.items():
        assert rms == pytest.approx(rows[run], rel=1e-6), run
    # And `show` prints the same equations.
    assert run_cli("show", str(path)).splitlines()[0] == model.equations()[0]
    again = ctsid.load(str(path))
    assert again.to_json() == model.to_json()


def test_derive_estimates_derivatives_with_sigmas():
    t = np.arange(800) * 0.01
    y = np.sin(2 * t) + 1e-3 * np.random.default_rng(0).standard_normal(800)
    values, sigmas = ctsid.derive(y, 0.01, 2)
    assert values.shape == sigmas.shape == (3, 800)
    inner = slice(100, 700)
    assert np.max(np.abs(values[2][inner] + 4 * np.sin(2 * t[inner]))) < 0.2
    assert np.all(sigmas[2][inner] > 0)


def test_frames_arrays_and_lists_of_runs_are_the_same_data(fitted):
    data, model = fitted
    one = data[data.run == 10]
    as_frame = model.simulate(one)
    as_array = model.simulate(one[["y", "u"]].to_numpy(), columns=["y", "u"])
    as_list = model.simulate([one, one])
    np.testing.assert_array_equal(as_frame, as_array)
    np.testing.assert_array_equal(as_list["1"], as_frame)


def test_discover_runs_and_returns_a_model_that_simulates(throttle, fitted):
    data, model = fitted
    found = ctsid.discover(data, model, tau=TAU, run_column="run", **{k: SETTINGS[k] for k in ("train", "validation", "test")})
    assert found.verdict in found.text
    assert found.model.simulate(data[data.run == 11]).shape == (1000, 1)


@pytest.mark.parametrize(
    "make, needle",
    [
        (lambda d: d.assign(y=d.y.where(d.index != 5, np.nan)), "not a finite number"),
        (lambda d: d.drop(columns=["u"]), "column 'u' not found"),
        (lambda d: d.assign(u=0.5), "constant"),
        # A lost run id is refused, not grouped into a run of its own.
        (lambda d: d.assign(run=d.run.where(d.index != 7, np.nan)), "row 7: no run id"),
    ],
)
def test_bad_data_raise_the_cli_one_line_messages(fitted, make, needle):
    data, _ = fitted
    with pytest.raises(ctsid.CtsidError, match=needle) as e:
        ctsid.identify(make(data), outputs=["y"], inputs=["u"], tau=TAU, run_column="run", degree=1)
    assert "\n" not in str(e.value)


def test_wrong_shapes_and_settings_raise_clear_errors(fitted):
    data, model = fitted
    with pytest.raises(ValueError, match="1-D array"):
        ctsid.identify(np.zeros(100), outputs=["y"], tau=TAU)
    with pytest.raises(ValueError, match="columns"):
        model.simulate(np.zeros((100, 3)), columns=["y", "u"])
    with pytest.raises(ValueError, match="1-D"):
        ctsid.derive(np.zeros((10, 2)), 0.01, 1)
    # Checked as the command line checks a column: a signal too small to compute with, a spike.
    wave = np.sin(np.arange(600) * 0.01)
    with pytest.raises(ctsid.CtsidError, match="too small"):
        ctsid.derive(1e-160 * wave, 0.01, 2)
    with pytest.raises(ctsid.CtsidError, match="row 7"):
        ctsid.derive(np.where(np.arange(600) == 7, 1e149, wave), 0.01, 2)
    with pytest.raises(ctsid.CtsidError, match="engine"):
        ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run", engine="tpu")
    # A frame of several runs given without run_column joined them end to end, and scored a
    # plausible fit (85.9 % on 30 throttle runs).
    with pytest.raises(ctsid.CtsidError, match="run_column='run'"):
        model.score(data)
    with pytest.raises(ctsid.CtsidError, match="12 different values"):
        ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, **SETTINGS)
    # The times are not read: a tau ten times the time column's step scored -264 % silently.
    with pytest.raises(ctsid.CtsidError, match="column 't' steps by 0.003 s but tau is 0.03 s"):
        model.score(data, tau=10 * TAU, run_column="run")
    # The same times in ms are the same sampling.
    in_ms = data.assign(t=1000 * data.t).rename(columns={"t": "t_ms"})
    assert model.score(in_ms, tau=TAU, run_column="run") == model.score(data, run_column="run")
    # Run lists as lists of ids give the model the strings give.
    lists = dict(SETTINGS, train=list(range(8)), validation=[8.0, 9], test=["10", 11])
    listed = ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run", **lists)
    assert same_model(listed, model)
    with pytest.raises(ctsid.CtsidError, match="used twice"):
        ctsid.identify({1: data[data.run == 0], "1": data[data.run == 1]}, outputs=["y"], inputs=["u"], tau=TAU)
    with pytest.raises(ctsid.CtsidError, match="99"):
        ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run", test="99")
    with pytest.raises(ctsid.CtsidError):
        ctsid.Model.from_json('{"format": "ctsid-model/2", "inputs": [], "outputs": [{"name": "y", "order": 1, "terms": [{"exponent": {"y": 1}, "coefficient": 1}]}]}')


def test_settings_of_the_wrong_kind_are_refused_not_coerced(fitted, tmp_path):
    """A second probe's findings: each of these ran with a silently changed setting or data."""
    data, model = fitted
    base = dict(outputs=["y"], inputs=["u"], tau=TAU, run_column="run", train="0-7", test="10-11")
    with pytest.raises(TypeError, match="degree"):
        ctsid.identify(data, degree=2.7, order=3, **base)  # was degree 2
    with pytest.raises(TypeError, match="refine"):
        ctsid.identify(data, degree=2, order=3, refine="no", **base)  # bool("no") is True
    with pytest.raises(ValueError, match="one of them"):
        ctsid.identify(data, degree=2, order=3, orders=[1, 2], **base)  # orders was ignored
    with pytest.raises(TypeError, match="terms"):
        ctsid.identify(data, degree=2, order=3, terms="sign(y_d1)", **base)  # split into letters
    with pytest.raises(TypeError, match="order"):
        ctsid.derive(data.y[:600].to_numpy(), TAU, 2.9)  # was order 2
    with pytest.raises(ctsid.CtsidError, match="not numbers"):
        ctsid.derive(data.y[:600].to_numpy() + 1j, TAU, 2)  # the imaginary part was dropped
    # Two columns of one name: the later one was used (here the noise column as y).
    runs = [g[["y", "u"]].to_numpy() for _, g in data.groupby("run")]
    junk = [np.c_[r[:, 0], np.zeros(len(r)), r[:, 1]] for r in runs]
    with pytest.raises(ctsid.CtsidError, match="named twice"):
        ctsid.identify(junk, outputs=["y"], inputs=["u"], tau=TAU, columns=["y", "y", "u"])
    # run_column on a list of frames: every run was joined into one.
    with pytest.raises(ValueError, match="run_column"):
        ctsid.identify([data], outputs=["y"], inputs=["u"], tau=TAU, run_column="run", degree=2, order=3)
    with pytest.raises(TypeError, match="file name"):
        model.save(None)  # wrote a file named None
    with pytest.raises(TypeError, match="ctsid.Model"):
        ctsid.discover(data, None, tau=TAU, run_column="run")
    # A constant measured output: the command line prints "-", Python gave inf and -inf.
    rows = model.score(data[data.run == 0].assign(y=1.0), run_column="run")
    assert rows[0]["nrmse"] is None and rows[0]["fit_percent"] is None
    # A numpy integer is an integer.
    same = ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run",
                          **dict(SETTINGS, degree=np.int64(2), order=np.int64(3)))
    assert same_model(same, model)


def test_findings_of_the_tenth_reading(fitted):
    """Masked samples, a missing-value code, run ids with commas, huge integers, None names."""
    data, _ = fitted
    run0 = data[data.run == 0][["y", "u"]].to_numpy()
    mask = np.zeros_like(run0, dtype=bool)
    mask[300:310, 0] = True
    # The mask was dropped and the values under it fitted.
    with pytest.raises(ctsid.CtsidError, match="10 masked"):
        ctsid.identify(np.ma.masked_array(run0, mask), columns=["y", "u"], outputs=["y"],
                       inputs=["u"], tau=TAU, degree=1, order=3)
    with pytest.raises(ctsid.CtsidError, match="masked"):
        ctsid.derive(np.ma.masked_array(run0[:, 0], mask[:, 0]), TAU, 2)
    # A missing-value code in a run: the command line notes it, the package said nothing.
    coded = run0.copy()
    coded[300, 0] = -1e7
    with pytest.warns(UserWarning, match="run '0': row 300, column 'y'"):
        ctsid.derive(coded[:, 0], TAU, 1)
    # Warnings turned into errors are raised as errors, not lost.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match="row 300"):
            ctsid.derive(coded[:, 0], TAU, 1)
    # A run id with a comma cannot be named in a run list.
    with pytest.raises(ctsid.CtsidError, match="comma"):
        ctsid.identify({"a,b": run0, "c": run0}, columns=["y", "u"], outputs=["y"],
                       inputs=["u"], tau=TAU, degree=1, order=3, test=["a,b"])
    with pytest.raises(ValueError, match="degree: .* beyond"):
        ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run",
                       degree=2**70, order=3)
    with pytest.raises(TypeError, match="outputs: give a list"):
        ctsid.identify(data, outputs=None, inputs=["u"], tau=TAU, run_column="run",
                       degree=1, order=3)
    # A named term over a state only order 4 has, where the search takes a lower order: the term
    # was dropped without a word; the command line notes it.
    with pytest.warns(UserWarning, match="'sign\\(y_d3\\)' was a candidate at no chosen order"):
        m = ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run",
                           train="0-7", validation="8-9", degree=2, orders=[2, 3, 4],
                           terms=["sign(y_d3)"])
    assert m.orders[0] < 4
    with pytest.raises(ctsid.CtsidError, match="no data rows"):
        ctsid.identify(data.iloc[:0], outputs=["y"], inputs=["u"], tau=TAU, degree=1, order=3)
    with pytest.raises(ctsid.CtsidError, match="'y' is the run column"):
        ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="y", degree=1,
                       order=3)


def test_an_interrupt_in_a_progress_line_is_raised_as_itself(fitted):
    """Ctrl-C arrives as a KeyboardInterrupt inside `logging` while a progress line is logged; it
    came out as a chain of `SystemError: ... returned a result with an exception set`, which
    `except KeyboardInterrupt` does not catch. A handler that raises it stands in for the key."""
    data, _ = fitted

    class Stop(logging.Handler):
        def emit(self, record):
            raise KeyboardInterrupt

    log, stop = logging.getLogger("ctsid"), Stop()
    level = log.level
    log.addHandler(stop)
    log.setLevel(logging.INFO)
    try:
        with pytest.raises(KeyboardInterrupt):
            ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run", **SETTINGS)
    finally:
        log.removeHandler(stop)
        log.setLevel(level)
    # The next call starts clean.
    again = ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run", **SETTINGS)
    assert same_model(again, fitted[1])


def test_an_error_pickles_as_itself():
    """A worker process's CtsidError reached its parent as a PicklingError (the class was named
    `_ctsid.CtsidError`, which pickle could not find)."""
    e = pickle.loads(pickle.dumps(ctsid.CtsidError("run '3': no data rows")))
    assert type(e) is ctsid.CtsidError and str(e) == "run '3': no data rows"


def test_a_model_pickles_and_simulates_as_before(fitted):
    """`Model` did not pickle, so it could not cross to a multiprocessing worker or a cache."""
    data, model = fitted
    for again in (pickle.loads(pickle.dumps(model)), copy.deepcopy(model)):
        assert type(again) is ctsid.Model
        assert again.to_json() == model.to_json() and again.summary == model.summary
        a = again.simulate(data, run_column="run")["10"]
        assert np.array_equal(a, model.simulate(data, run_column="run")["10"])


def test_segment_cuts_runs_as_the_command_line_does(throttle, fitted, tmp_path):
    """`segment=` is the command line's `--segment`: the same pieces, names and scores."""
    data, model = fitted
    one = data[data["run"] == 10].drop(columns=["run"])
    rows = model.score(one, segment=1.5)
    assert [r["run"] for r in rows] == ["0", "1"]
    path = tmp_path / "model.json"
    model.save(str(path))
    run10 = tmp_path / "run10.csv"
    one.to_csv(run10, index=False)
    printed = run_cli("simulate", str(path), str(run10), "--tau", str(TAU), "--segment", "1.5")
    cli_rms = {l.split()[0]: float(l.split()[2]) for l in printed.splitlines()[1:] if l.split()[1] == "y"}
    for r in rows:
        assert r["rms"] == pytest.approx(cli_rms[r["run"]], rel=1e-6), r
    # Run lists name a run for all its pieces, as on the command line.
    cut = ctsid.identify(data, outputs=["y"], inputs=["u"], tau=TAU, run_column="run",
                         segment=1.5, **SETTINGS)
    out = tmp_path / "cli.json"
    run_cli(
        "identify", str(throttle), "--output", "y", "--input", "u", "--run-column", "run",
        "--tau", str(TAU), "--train", "0-7", "--validation", "8-9", "--test", "10-11",
        "--degree", "2", "--order", "3", "--segment", "1.5", "--quiet", "-o", str(out),
    )
    from_cli = ctsid.load(str(out))
    assert cut.equations() == from_cli.equations()
    assert [c["coefficient"] for c in cut.coefficients()] == [
        c["coefficient"] for c in from_cli.coefficients()
    ]
    assert cut.equations() != model.equations()  # the pieces are other runs than the whole
    with pytest.raises(ctsid.CtsidError, match="less than 2 samples"):
        model.score(one, segment=0.003)
    # Pieces too short for the model say which option to change, as on the command line.
    with pytest.raises(ctsid.CtsidError, match="give a longer segment="):
        model.score(one, segment=0.012)
    # discover takes the same pieces.
    found = ctsid.discover(data, model, run_column="run", segment=1.5, train="0-7",
                           validation="8-9", test="10-11")
    assert "| 10#1 | test |" in found.text, found.text
    with pytest.raises(TypeError, match="segment"):
        model.score(one, segment="1.5")


def test_a_level_held_at_its_top_is_read_as_a_limit_unless_limits_is_false():
    # y' = -y + u with the level held at 0.8 (an overflow), Euler at a tenth of the sampling.
    tau, rng = 0.05, np.random.default_rng(3)
    frames = []
    for run in range(6):
        t = np.arange(400) * tau
        u = sum(a * np.sin(w * t + p) for a, w, p in rng.uniform([0.3, 0.3, 0], [0.7, 2.0, 6], (3, 3)))
        y, x = np.empty(len(t)), 0.0
        for k in range(len(t)):
            y[k] = x
            for _ in range(10):
                x = min(x + tau / 10 * (-x + u[k]), 0.8)
        frames.append(pd.DataFrame({"run": run, "y": y, "u": u}))
    data = pd.concat(frames)
    settings = dict(tau=tau, run_column="run", train="0-3", validation="4", test="5", degree=1, order=1)
    with pytest.warns(UserWarning, match="holds its largest value 0.8"):
        held = ctsid.identify(data, outputs=["y"], inputs=["u"], **settings)
    assert json.loads(held.to_json())["outputs"][0]["limits"] == {"max": 0.8}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        free = ctsid.identify(data, outputs=["y"], inputs=["u"], limits=False, **settings)
    assert "limits" not in json.loads(free.to_json())["outputs"][0]
