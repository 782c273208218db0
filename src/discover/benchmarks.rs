//! Real-data setups for `discover` on the measured benchmarks in `../shared/data` (see each
//! record's README there): Silverbox (an electronic Duffing oscillator) against a linear
//! nominal, EMPS (a prismatic joint) against mass and viscous friction. Used by the examples
//! `silverbox_discover` and `emps_discover` and by `tests/discover_real.rs`.

use nalgebra::{DMatrix, DVector};

use super::Options;
use crate::derivatives::{differentiate_runs, DerivativeOptions};
use crate::error::{Error, Result};
use crate::model::{Model, OutputEquation, Term};
use crate::records::{CsvSpec, RecordSet, Run};
use crate::simulate::{free_run, RunData, SimOptions};

/// Records, nominal model and options of one benchmark, and how many samples the benchmark's
/// convention gives a model to set its initial state (scored on the rest).
pub struct Setup {
    pub records: RecordSet,
    pub nominal: Model,
    pub options: Options,
    pub init_samples: usize,
}

/// The named columns of a single-run CSV through the crate's record loader (so a missing column
/// or a bad value is the usual one-line error), one vector per column. The benchmarks' time
/// columns are rounded to a few digits, so the known sampling period is given instead; the
/// sample index `k` and the time `t_s` every benchmark file carries are checked against it
/// ([`check_sample_index`]), since the protocols read samples by position.
pub(crate) fn columns(path: &str, names: &[&str], tau: f64) -> Result<Vec<Vec<f64>>> {
    let mut all: Vec<String> = names.iter().map(|c| c.to_string()).collect();
    all.extend(["k".to_string(), "t_s".to_string()]);
    let spec = CsvSpec {
        columns: all,
        run_column: None,
        time_column: None,
        tau: Some(tau),
        rows_independent: false,
    };
    let rs = RecordSet::from_csv(path, &spec)?;
    let Some(run) = rs.runs.into_iter().next() else {
        return Ok(Vec::new());
    };
    let mut cols = run.channels;
    let t = cols.pop().unwrap_or_default();
    let k = cols.pop().unwrap_or_default();
    check_sample_index(path, (&k, &t, &run.rows), tau)?;
    Ok(cols)
}

/// The benchmark files' `k` counts the samples from 0 in file order and `t_s = k tau` (to a
/// quarter of a step: the stamps are rounded to a few digits): a shuffled, cut or resampled file
/// would otherwise be split and scored by position as if it were the benchmark's.
fn check_sample_index(
    path: &str,
    (k, t, rows): (&[f64], &[f64], &[usize]),
    tau: f64,
) -> Result<()> {
    let bad = |i: usize, what: String| {
        Err(Error::InvalidData(format!(
            "{path}: row {}: {what}; the benchmark reads samples by position: is it the benchmark's file, whole and in order?",
            rows.get(i).copied().unwrap_or(i + 2)
        )))
    };
    for (i, (&ki, &ti)) in k.iter().zip(t).enumerate() {
        if ki != i as f64 {
            return bad(
                i,
                format!(
                    "column 'k' is {} where sample {i} was expected",
                    crate::util::short(ki)
                ),
            );
        }
        if (ti - ki * tau).abs() > 0.25 * tau {
            return bad(
                i,
                format!(
                    "column 't_s' is {} where k * {} = {} was expected",
                    crate::util::short(ti),
                    crate::util::short(tau),
                    crate::util::short(ki * tau)
                ),
            );
        }
    }
    Ok(())
}

fn run(id: &str, y: &[f64], u: &[f64], first_row: usize) -> Run {
    Run {
        id: id.into(),
        channels: vec![y.to_vec(), u.to_vec()],
        t0: 0.0,
        rows: (first_row..first_row + y.len()).collect(),
    }
}

/// Silverbox (`SNLS80mV.csv`): the training multisine (samples 40650..105712) in 6 runs (train
/// 4, validation 2), the full arrow (100..40575) as the test run; the nominal
/// `y'' = a0 y + a1 y' + b u + c` by least squares on smoothed derivatives of the training runs.
/// Refuses a file that [`RecordSet::from_csv`] refuses (missing, or without the `u_V` and `y_V`
/// columns) or that has fewer than 105,712 rows, and errs when the derivatives or the nominal's
/// least squares fail.
pub fn silverbox(path: &str) -> Result<Setup> {
    let tau = 1.0 / 610.3515625;
    let c = columns(path, &["u_V", "y_V"], tau)?;
    let (u, y) = (&c[0], &c[1]);
    if y.len() < 105712 {
        return Err(Error::param("benchmark", format!("{path}: too few rows")));
    }
    let (a, b) = (40650usize, 105712usize);
    let chunk = (b - a) / 6;
    let mut runs: Vec<Run> = (0..6)
        .map(|k| {
            let (s, e) = (a + k * chunk, a + (k + 1) * chunk);
            run(&format!("ms{k}"), &y[s..e], &u[s..e], s + 2)
        })
        .collect();
    runs.push(run("arrow", &y[100..40575], &u[100..40575], 102));
    let records = RecordSet::new(tau, vec!["y".into(), "u".into()], runs)?;
    let train = vec![0, 1, 2, 3];
    let ys: Vec<&[f64]> = train
        .iter()
        .map(|&r| records.runs[r].channels[0].as_slice())
        .collect();
    let der = differentiate_runs(&ys, tau, 2, &DerivativeOptions::default())?;
    let mut rows = Vec::new();
    let mut lab = Vec::new();
    for (k, &r) in train.iter().enumerate() {
        let d = &der[k];
        let uu = &records.runs[r].channels[1];
        for i in 50..uu.len() - 50 {
            rows.push([d.values[0][i], d.values[1][i], uu[i], 1.0]);
            lab.push(d.values[2][i]);
        }
    }
    let x = DMatrix::from_fn(rows.len(), 4, |i, j| rows[i][j]);
    let th = x
        .svd(true, true)
        .solve(&DVector::from_column_slice(&lab), 1e-12)
        .map_err(|e| Error::Numerical(format!("Silverbox nominal: {e}")))?;
    let nominal = Model::new(
        &["u"],
        vec![OutputEquation::new(
            "y",
            2,
            vec![
                Term::new(&[("y", 1)], th[0]),
                Term::new(&[("y_d1", 1)], th[1]),
                Term::new(&[("u", 1)], th[2]),
                Term::new(&[], th[3]),
            ],
        )],
        Some(tau),
    );
    let mut options = Options::new(train, vec![4, 5], vec![6]);
    options.refine_iterations = 15;
    Ok(Setup {
        records,
        nominal,
        options,
        init_samples: 50,
    })
}

/// EMPS: the estimation record in 6 runs (train 4, validation 2), the pulses record as the test
/// run; input the motor force `force_N`, output the position `q_m`; nominal
/// `q'' = -(Fv / M) q' + force / M` with the published M = 95.1089 kg, Fv = 203.5034 N s/m. Refuses
/// files that [`RecordSet::from_csv`] refuses (missing, or without the `q_m` and `force_N` columns)
/// and runs that [`RecordSet::new`] refuses.
pub fn emps(dir: &str) -> Result<Setup> {
    let cols = ["q_m", "force_N"];
    let tr = columns(&format!("{dir}/EMPS_train_DATA_EMPS.csv"), &cols, 1e-3)?;
    let te = columns(
        &format!("{dir}/EMPS_test_DATA_EMPS_PULSES.csv"),
        &cols,
        1e-3,
    )?;
    let (q, f) = (&tr[0], &tr[1]);
    let chunk = q.len() / 6;
    let mut runs: Vec<Run> = (0..6)
        .map(|k| {
            let (s, e) = (k * chunk, (k + 1) * chunk);
            run(&format!("est{k}"), &q[s..e], &f[s..e], s + 2)
        })
        .collect();
    runs.push(run("pulses", &te[0], &te[1], 2));
    // The record's own column names, so that the model files written from it simulate on the
    // record's files with `ctsid simulate`.
    let records = RecordSet::new(1e-3, cols.iter().map(|c| c.to_string()).collect(), runs)?;
    let (m, fv) = (95.1089, 203.5034);
    let nominal = Model::new(
        &["force_N"],
        vec![OutputEquation::new(
            "q_m",
            2,
            vec![
                Term::new(&[("q_m_d1", 1)], -fv / m),
                Term::new(&[("force_N", 1)], 1.0 / m),
            ],
        )],
        Some(1e-3),
    );
    let mut options = Options::new(vec![0, 1, 2, 3], vec![4, 5], vec![6]);
    options.refine_iterations = 15;
    Ok(Setup {
        records,
        nominal,
        options,
        init_samples: 20,
    })
}

/// Free-run RMS error of `m` on `run` after its first `init` samples, from an initial state
/// fitted on those samples (infinite when the simulation fails).
pub fn rms_after(m: &Model, run: &RunData, init: usize) -> f64 {
    let sim = m
        .compile()
        .and_then(|c| free_run(&c, run, init, &SimOptions::default()));
    match sim {
        Ok(s) if s[0].len() > init => crate::metrics::rms(&s[0][init..], &run.y[0][init..]),
        _ => f64::INFINITY,
    }
}
