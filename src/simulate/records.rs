//! Free runs of a model on every run of a record set, with their scores: what `ctsid simulate`
//! prints, as a library call ([`Model::simulate`]).

use rayon::prelude::*;

use super::{free_run, RunData, SimOptions, INIT_WINDOW};
use crate::error::Result;
use crate::metrics::rms_nrmse;
use crate::model::Model;
use crate::records::{RecordSet, Run};

/// One run simulated: the simulated outputs and their scores against the measured ones.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// The run's id in the record set.
    pub id: String,
    /// `simulated[output][sample]`, in the model's output order.
    pub simulated: Vec<Vec<f64>>,
    /// Per output: RMS of simulated minus measured, in the output's units.
    pub rms: Vec<f64>,
    /// Per output: RMS over the measured output's standard deviation (infinite for a
    /// constant output).
    pub nrmse: Vec<f64>,
}

impl RunResult {
    /// Per output: the fit in percent, `100 (1 - NRMSE)` (MATLAB's `compare`).
    pub fn fit_percent(&self) -> Vec<f64> {
        self.nrmse.iter().map(|e| 100.0 * (1.0 - e)).collect()
    }
}

/// Free runs of a model on a record set ([`Model::simulate`]).
#[derive(Debug, Clone)]
pub struct Simulation {
    /// The model's output names, the order of every per-output vector here.
    pub outputs: Vec<String>,
    pub runs: Vec<RunResult>,
    /// Per output, over all runs pooled.
    pub rms: Vec<f64>,
    pub nrmse: Vec<f64>,
}

/// A run of `records` as the model's outputs and inputs, found by name (`channels[c]` is the
/// record set's channel `c`). Refuses a record set without one of the model's channels.
pub fn run_data(model: &Model, records: &RecordSet, run: &Run) -> Result<RunData> {
    let pick = |names: Vec<&String>| -> Result<Vec<Vec<f64>>> {
        names
            .into_iter()
            .map(|n| Ok(run.channels[records.channel_index(n)?].clone()))
            .collect()
    };
    Ok(RunData {
        id: run.id.clone(),
        // Time since the run's start: the model is time invariant, and stamps far from zero
        // (Unix time) would leave the integrator a few digits of resolution.
        t: (0..run.len()).map(|k| k as f64 * records.tau).collect(),
        y: pick(model.outputs.iter().map(|o| &o.name).collect())?,
        u: pick(model.inputs.iter().collect())?,
        states: None,
        x0: Vec::new(),
    })
}

impl Model {
    /// Simulates the model on every run of `records` from the measured inputs, each from the
    /// initial state fitted on its first [`INIT_WINDOW`] samples (the convention of every score
    /// ctsid prints), and scores it against the measured outputs.
    ///
    /// The record set must hold a channel for each output and input of the model, by name.
    /// Fails on the first run that cannot be simulated (too short, or the model diverges or has
    /// an unstable mode there), naming the run. From an initial state of your own, without
    /// measured outputs: [`crate::simulate::simulate_model`].
    ///
    /// ```no_run
    /// use ctsid::{Model, RecordSet};
    /// let model = Model::read("emps.model.json")?;
    /// let records = RecordSet::read_csv("emps.csv", &["q_m", "force_N"], Some("run"), 1e-3)?;
    /// let sim = model.simulate(&records)?;
    /// for run in &sim.runs {
    ///     println!("run {}: fit {:.1} %", run.id, run.fit_percent()[0]);
    /// }
    /// # Ok::<(), ctsid::Error>(())
    /// ```
    pub fn simulate(&self, records: &RecordSet) -> Result<Simulation> {
        self.simulate_with(records, INIT_WINDOW, &SimOptions::default())
    }

    /// [`Model::simulate`] with another initial-state window and integrator settings.
    pub fn simulate_with(
        &self,
        records: &RecordSet,
        window: usize,
        opts: &SimOptions,
    ) -> Result<Simulation> {
        let compiled = self.compile()?;
        let data: Vec<RunData> = records
            .runs
            .iter()
            .map(|r| run_data(self, records, r))
            .collect::<Result<_>>()?;
        let runs: Vec<RunResult> = data
            .par_iter()
            .map(|d| {
                let simulated = free_run(&compiled, d, window, opts)?;
                let (rms, nrmse) = simulated
                    .iter()
                    .zip(&d.y)
                    .map(|(s, y)| rms_nrmse(s, y))
                    .unzip();
                Ok(RunResult {
                    id: d.id.clone(),
                    simulated,
                    rms,
                    nrmse,
                })
            })
            .collect::<Result<_>>()?;
        let n_out = self.outputs.len();
        let (rms, nrmse) = (0..n_out)
            .map(|i| {
                let sim: Vec<f64> = runs.iter().flat_map(|r| r.simulated[i].clone()).collect();
                let meas: Vec<f64> = data.iter().flat_map(|d| d.y[i].clone()).collect();
                rms_nrmse(&sim, &meas)
            })
            .unzip();
        Ok(Simulation {
            outputs: self.outputs.iter().map(|o| o.name.clone()).collect(),
            runs,
            rms,
            nrmse,
        })
    }
}
