//! Python bindings of ctsid: a thin layer over the library's entry points, used by the Python
//! package `ctsid` (`python/ctsid/__init__.py`), which turns numpy arrays and pandas frames into
//! the plain lists these functions take and wraps what they return.
//!
//! Conventions: records cross as `(tau, names, runs)`, each run `(id, columns)` with one list of
//! floats per name; every error of the library is raised as `CtsidError` (a `ValueError`) with
//! the one-line message the command line prints; long calls release the GIL; progress lines go
//! to the `logging` logger "ctsid" at INFO level, never to standard output.

use ctsid::discover::{discover as discover_rs, Options};
use ctsid::engine::select::EngineChoice;
use ctsid::identify::split::{parse_list_at_most, resolve};
use ctsid::identify::{identify as identify_rs, Orders, Settings};
use ctsid::records::{RecordSet, Run};
use ctsid::Split;
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

// Named in the package's module, where `ctsid.CtsidError` re-exports it: pickle looks the class
// up by that name (as `_ctsid.CtsidError`, a worker's error reached its parent as a PicklingError).
create_exception!(
    ctsid,
    CtsidError,
    PyValueError,
    "An error from ctsid: bad data or settings, with the one-line message the command line prints."
);

fn err(e: ctsid::Error) -> PyErr {
    CtsidError::new_err(e.to_string())
}

/// [`err`] for a call on runs cut into pieces of `segment` seconds: a piece too short says to
/// give a longer `segment=`, as the command line says of `--segment`.
fn err_in(segment: Option<f64>) -> impl Fn(ctsid::Error) -> PyErr {
    move |e| match segment {
        Some(s) => err(ctsid::records::piece_too_short(e, s, "segment=")),
        None => err(e),
    }
}

/// A run as it crosses from Python: its id and one column of samples per channel name.
type PyRun = (String, Vec<Vec<f64>>);

/// One simulated run back to Python: id, simulated outputs, RMS and NRMSE per output.
type SimulatedRun = (String, Vec<Vec<f64>>, Vec<f64>, Vec<f64>);

/// Per derivative order k, one value per sample.
type Rows = Vec<Vec<f64>>;

/// The record set of `runs`, checked as the CSV reader checks a file (non-finite values, too few
/// samples, columns of different lengths). Sample `k` of a run is "row k" in messages. Samples
/// that look like a missing-value code or a glitch (legal values, kept) are warned of as the
/// command line notes them (a `UserWarning`, "run 'ID': row K, column 'C': ..."): without it a
/// `-9999` in a run was fitted and the package said nothing. Built with the GIL held, so that a
/// warning turned into an error (`warnings.simplefilter("error")`) is raised, not lost.
fn record_set(
    py: Python<'_>,
    tau: f64,
    names: Vec<String>,
    runs: Vec<PyRun>,
) -> PyResult<RecordSet> {
    let runs = runs
        .into_iter()
        .map(|(id, channels)| {
            let n = channels.first().map_or(0, Vec::len);
            Run {
                id,
                channels,
                t0: 0.0,
                rows: (0..n).collect(),
            }
        })
        .collect();
    let rs = RecordSet::new(tau, names, runs).map_err(err)?;
    let warnings = py.import("warnings")?;
    for s in rs.suspect_samples() {
        let text = format!("ctsid: run '{}': {}", s.run, s.note());
        warnings.call_method1(
            "warn",
            (text, py.get_type::<pyo3::exceptions::PyUserWarning>(), 2),
        )?;
    }
    Ok(rs)
}

/// Train, validation and test runs from the run lists the CLI takes (`"0-3"`, `"a,b"`): training
/// defaults to every run not named elsewhere, test to none.
fn split(
    rs: &RecordSet,
    train: Option<&str>,
    validation: Option<&str>,
    test: Option<&str>,
) -> ctsid::Result<Split> {
    let ids: Vec<String> = rs.runs.iter().map(|r| r.id.clone()).collect();
    let list = |text: &str, what: &str| -> ctsid::Result<Vec<usize>> {
        resolve(
            &parse_list_at_most(text, what, ids.len().max(1))?,
            &ids,
            what,
        )
    };
    let validation = validation.map(|v| list(v, "validation")).transpose()?;
    let test = test
        .map(|t| list(t, "test"))
        .transpose()?
        .unwrap_or_default();
    let train = match train {
        Some(t) => list(t, "train")?,
        None => (0..ids.len())
            .filter(|r| !test.contains(r) && !validation.iter().flatten().any(|v| v == r))
            .collect(),
    };
    Split::new(train, validation, test, &ids)
}

/// The record set of `runs`, cut into pieces of `segment` seconds where given
/// (`RecordSet::segmented_seconds`, the command line's `--segment`).
fn pieces(
    py: Python<'_>,
    tau: f64,
    names: Vec<String>,
    runs: Vec<PyRun>,
    segment: Option<f64>,
) -> PyResult<RecordSet> {
    let rs = record_set(py, tau, names, runs)?;
    match segment {
        Some(s) => rs.segmented_seconds(s).map_err(err),
        None => Ok(rs),
    }
}

/// The record set of `runs` (cut into pieces of `segment` seconds where given) and its split by
/// the run lists `[train, validation, test]`.
fn records_and_split(
    py: Python<'_>,
    tau: f64,
    names: Vec<String>,
    runs: Vec<PyRun>,
    [train, validation, test]: [Option<String>; 3],
    segment: Option<f64>,
) -> PyResult<(RecordSet, Split)> {
    let rs = pieces(py, tau, names, runs, segment)?;
    let sp = split(
        &rs,
        train.as_deref(),
        validation.as_deref(),
        test.as_deref(),
    )
    .map_err(err)?;
    Ok((rs, sp))
}

/// The first error a progress line raised in Python (Ctrl-C arrives as a `KeyboardInterrupt`
/// raised inside `logging`), kept until the call returns: one per call, so two threads'
/// identifications never see each other's. Restored into the interpreter at once, it left an
/// exception set under the library's next calls into Python: a chain of `SystemError: ...
/// returned a result with an exception set` instead of the interrupt.
type Pending = std::sync::Arc<std::sync::Mutex<Option<PyErr>>>;

/// Progress lines of the long stages, to the `logging` logger "ctsid" (looked up for each line,
/// so a handler the user adds mid-call counts). After an error no more lines are logged; the
/// call raises it when it ends ([`raise_pending`]).
fn log_progress(pending: Pending) -> ctsid::identify::Progress {
    ctsid::identify::Progress::new(move |line: &str| {
        if pending.lock().unwrap_or_else(|e| e.into_inner()).is_some() {
            return;
        }
        // The lock is not held while Python runs: the handler may take as long as it likes.
        let logged = Python::attach(|py| {
            py.import("logging")
                .and_then(|m| m.call_method1("getLogger", ("ctsid",)))
                .and_then(|l| l.call_method1("info", (line,)))
                .map(|_| ())
        });
        if let Err(e) = logged {
            pending
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .get_or_insert(e);
        }
    })
}

/// The error a progress line raised during the call that just ended, if any.
fn raise_pending(pending: &Pending) -> PyResult<()> {
    let e = pending.lock().unwrap_or_else(|e| e.into_inner()).take();
    e.map_or(Ok(()), Err)
}

/// A model file: polynomial and named terms per output, as `ctsid` writes and reads it.
#[pyclass(name = "Model", module = "ctsid._ctsid", frozen, skip_from_py_object)]
#[derive(Clone)]
pub struct PyModel {
    inner: ctsid::Model,
}

#[pymethods]
impl PyModel {
    /// The model of a JSON text (`ctsid-model/2`), checked strictly.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<PyModel> {
        let inner = ctsid::Model::from_json_str(text, "<json>").map_err(err)?;
        Ok(PyModel { inner })
    }

    /// Reads a model file.
    #[staticmethod]
    fn load(path: &str) -> PyResult<PyModel> {
        let inner = ctsid::Model::read(path).map_err(err)?;
        Ok(PyModel { inner })
    }

    /// The model as the JSON text of its file.
    fn to_json(&self) -> PyResult<String> {
        self.inner.to_json_string().map_err(err)
    }

    /// Writes the model file (whole or not at all).
    fn save(&self, path: &str) -> PyResult<()> {
        self.inner.write(path).map_err(err)
    }

    /// One equation per output, `y_d2 = ...`.
    fn equations(&self) -> Vec<String> {
        self.inner.outputs.iter().map(|o| o.to_string()).collect()
    }

    #[getter]
    fn outputs(&self) -> Vec<String> {
        self.inner.outputs.iter().map(|o| o.name.clone()).collect()
    }

    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.inner.inputs.clone()
    }

    #[getter]
    fn orders(&self) -> Vec<usize> {
        self.inner.outputs.iter().map(|o| o.order).collect()
    }

    #[getter]
    fn tau(&self) -> Option<f64> {
        self.inner.tau
    }

    /// Per term: (output, term, coefficient, standard error or None).
    fn coefficients(&self) -> Vec<(String, String, f64, Option<f64>)> {
        let mut out = Vec::new();
        for o in &self.inner.outputs {
            for t in &o.terms {
                let name = t.expression.clone().unwrap_or_else(|| t.monomial());
                out.push((o.name.clone(), name, t.coefficient, t.std_error));
            }
        }
        out
    }

    /// Free runs on every run of the records (cut into pieces of `segment` seconds where
    /// given), each from the initial state fitted on its first samples: per run (id, simulated
    /// outputs, RMS per output, NRMSE per output).
    #[pyo3(signature = (tau, names, runs, segment=None))]
    fn simulate(
        &self,
        py: Python<'_>,
        tau: f64,
        names: Vec<String>,
        runs: Vec<PyRun>,
        segment: Option<f64>,
    ) -> PyResult<Vec<SimulatedRun>> {
        let rs = pieces(py, tau, names, runs, segment)?;
        let sim = py
            .detach(|| self.inner.simulate(&rs))
            .map_err(err_in(segment))?;
        Ok(sim
            .runs
            .into_iter()
            .map(|r| (r.id, r.simulated, r.rms, r.nrmse))
            .collect())
    }

    fn __str__(&self) -> String {
        self.inner.to_string()
    }

    fn __repr__(&self) -> String {
        format!("<ctsid.Model {}>", self.equations().join("; "))
    }
}

/// Identifies a model: the library's `Identifier` with the CLI's defaults. Returns the model
/// and a JSON summary (orders, test NRMSE per output, engine, refinement).
#[pyfunction]
#[pyo3(signature = (tau, names, runs, outputs, inputs, degree, train=None, validation=None,
    test=None, order=None, orders=None, terms=Vec::new(), engine="auto", refine=true, eta=None,
    segment=None, limits=true))]
#[allow(clippy::too_many_arguments)]
fn identify(
    py: Python<'_>,
    tau: f64,
    names: Vec<String>,
    runs: Vec<PyRun>,
    outputs: Vec<String>,
    inputs: Vec<String>,
    degree: usize,
    train: Option<String>,
    validation: Option<String>,
    test: Option<String>,
    order: Option<Vec<usize>>,
    orders: Option<Vec<usize>>,
    terms: Vec<String>,
    engine: &str,
    refine: bool,
    eta: Option<f64>,
    segment: Option<f64>,
    limits: bool,
) -> PyResult<(PyModel, String)> {
    let mut s = Settings::new(outputs, inputs, degree);
    if let Some(o) = order {
        s.orders = Orders::Fixed(o);
    } else if let Some(o) = orders {
        s.orders = Orders::Search(o);
    }
    if let Some(e) = eta {
        s.eta = e;
    }
    s.engine = engine.parse::<EngineChoice>().map_err(err)?;
    s.terms = terms;
    s.refine = refine;
    s.limits = limits;
    let pending = Pending::default();
    s.progress = Some(log_progress(pending.clone()));
    s.validate().map_err(err)?;
    let (rs, sp) = records_and_split(py, tau, names, runs, [train, validation, test], segment)?;
    let id = py.detach(|| identify_rs(&rs, &sp, &s));
    // An interrupt (or a logging failure) during the call is the call's result.
    raise_pending(&pending)?;
    let id = id.map_err(err_in(segment))?;
    let summary = serde_json::json!({
        "orders": id.model.outputs.iter().map(|o| o.order).collect::<Vec<_>>(),
        "test_nrmse": id.test_nrmse(),
        "engines": id.outputs.iter().map(|o| o.engine.clone()).collect::<Vec<_>>(),
        "refinement": id.refinement.as_ref().map(|r| r.message.clone()),
        "notes": id.notes,
    });
    // With its `training` section, as `ctsid identify -o` writes it.
    let inner = id.model_file();
    Ok((PyModel { inner }, summary.to_string()))
}

/// Self-tuning derivatives of one uniformly sampled signal: (values, sigmas), each a list of
/// `order + 1` lists (k = 0 is the smoothed signal). The signal is checked as `ctsid derive`
/// checks a column (a magnitude that underflows, a sample far beyond the rest), not only for
/// non-finite values: a signal of 1e-160 was smoothed at an arbitrary level without a word.
#[pyfunction]
fn derive(py: Python<'_>, y: Vec<f64>, tau: f64, order: usize) -> PyResult<(Rows, Rows)> {
    let rs = record_set(py, tau, vec!["y".into()], vec![("0".into(), vec![y])])?;
    let d = py
        .detach(|| ctsid::derivatives::differentiate(&rs.runs[0].channels[0], tau, order))
        .map_err(err)?;
    Ok((d.values, d.sigma))
}

/// Names what `nominal` misses on the records: (verdict, report text, augmented model,
/// test NRMSE before, after).
#[pyfunction]
#[pyo3(signature = (tau, names, runs, nominal, train=None, validation=None, test=None, seed=0,
    segment=None))]
#[allow(clippy::too_many_arguments)]
fn discover(
    py: Python<'_>,
    tau: f64,
    names: Vec<String>,
    runs: Vec<PyRun>,
    nominal: &PyModel,
    train: Option<String>,
    validation: Option<String>,
    test: Option<String>,
    seed: u64,
    segment: Option<f64>,
) -> PyResult<(String, String, PyModel, f64, f64)> {
    let nominal = &nominal.inner;
    let (rs, sp) = records_and_split(py, tau, names, runs, [train, validation, test], segment)?;
    let (d, augmented) = py
        .detach(|| {
            let mut o = Options::new(sp.train, sp.validation.unwrap_or_default(), sp.test);
            o.seed = seed;
            let d = discover_rs(&rs, nominal, &o)?;
            let augmented = d.augmented_model(nominal)?;
            Ok::<_, ctsid::Error>((d, augmented))
        })
        .map_err(err_in(segment))?;
    Ok((
        d.verdict.clone(),
        d.text(),
        PyModel { inner: augmented },
        d.nrmse_before,
        d.nrmse_after,
    ))
}

/// Writes the source paper's throttle experiment as CSV (`run,t,u,y` and, with `truth`, the
/// noise-free output and its derivatives): `runs` runs of `samples` samples every `tau` s,
/// noise `noise` (the paper's eta), from `seed`.
#[pyfunction]
#[pyo3(signature = (path, runs=100, samples=1000, tau=0.003, noise=0.03, seed=1, truth=false))]
#[allow(clippy::too_many_arguments)]
fn throttle_dataset(
    py: Python<'_>,
    path: &str,
    runs: usize,
    samples: usize,
    tau: f64,
    noise: f64,
    seed: u64,
    truth: bool,
) -> PyResult<()> {
    use ctsid::plants::{dataset, write_csv, Plant, ThrottlePreset};
    py.detach(|| {
        let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
        let data = dataset(&plant, runs, samples, tau, noise, seed)?;
        write_csv(&plant, &data, path, truth)
    })
    .map_err(err)
}

#[pymodule]
fn _ctsid(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("CtsidError", m.py().get_type::<CtsidError>())?;
    m.add_class::<PyModel>()?;
    m.add_function(wrap_pyfunction!(identify, m)?)?;
    m.add_function(wrap_pyfunction!(derive, m)?)?;
    m.add_function(wrap_pyfunction!(discover, m)?)?;
    m.add_function(wrap_pyfunction!(throttle_dataset, m)?)?;
    Ok(())
}
