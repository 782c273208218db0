//! Built-in plants with known truth, their excitation and measurement noise, and a dataset
//! generator: the test benches of the identification workflow.
//!
//! - [`throttle`]: the paper's electronic throttle (stiff, third order, aerodynamic term
//!   proportional to Patm; linear with known coefficients at Patm = 0).
//! - [`mimo`]: a 2-input, 3-output polynomial plant of relative degree 3 per output.
//! - [`excitation`]: the paper's damped, saturated multi-sine, with its saturation corners.
//! - [`noise`]: the paper's noise model; [`rng`]: the seeded generator behind every draw.
//!
//! [`dataset`] simulates runs from rest under independent excitation draws and returns, per run,
//! the input, the measured and true outputs, and the exact derivatives `0..=order+1` of every
//! output (computed from the state and the equations, not by differencing). Everything is a
//! pure function of the seed; run `r` draws from streams derived from `(seed, r)` only, so
//! asking for more runs leaves the first ones unchanged.

pub mod excitation;
pub mod mimo;
pub mod noise;
pub mod rng;
pub mod throttle;

/// Saturation level of the MIMO plant's default excitation.
pub const MIMO_U_BAR: f64 = 5.0;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::model::Model;
use crate::simulate::{simulate, Input, SimOptions, System};
use excitation::{ExcitationConfig, ExcitationInput};
use mimo::MimoPlant;
use rng::{stream_seed, Rng};
use throttle::{Throttle, ThrottleParams};

/// The dynamics of a built-in plant.
#[derive(Debug, Clone)]
pub enum Dynamics {
    Throttle(Throttle),
    /// Boxed: a compiled model is several times the throttle's size.
    Mimo(Box<MimoPlant>),
}

/// Presets of the throttle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ThrottlePreset {
    /// The paper's excitation (u_bar = 5, mu = 4, w_max = 10, n_B = 20) with the given ambient
    /// pressure (Pa); 0 makes the plant linear.
    Paper { patm: f64 },
    /// Patm = 101,325 Pa and the excitation mapped to `u in [-k, 0]`, k chosen so that the
    /// angle stays within [0, pi/2] (see [`Plant::throttle`]).
    Physical,
}

/// A built-in plant and the excitation family its runs use.
#[derive(Debug, Clone)]
pub struct Plant {
    pub name: String,
    pub dynamics: Dynamics,
    pub excitation: ExcitationConfig,
}

impl Plant {
    /// The electronic throttle.
    ///
    /// For [`ThrottlePreset::Physical`] the excitation is `u = -k (Sat(s) + u_bar) / (2 u_bar)`,
    /// so `u in [-k, 0]`. The linear part's impulse response is positive (three real poles, no
    /// zero), so the angle stays within `[y0 - G k, y0]` with `G = 1.222e6 / 23978 = 51` rad per
    /// unit of u; `k = (y0 - 0.5) / G` leaves 0.5 rad of margin above 0 for the aerodynamic
    /// torque, which closes the plate further (checked in the tests over many runs).
    pub fn throttle(preset: ThrottlePreset) -> Plant {
        match preset {
            ThrottlePreset::Paper { patm } => Plant {
                name: "throttle".into(),
                dynamics: Dynamics::Throttle(Throttle::new(ThrottleParams::paper(patm))),
                excitation: ExcitationConfig::paper(),
            },
            ThrottlePreset::Physical => {
                let th = Throttle::new(ThrottleParams::paper(throttle::PATM_STD));
                let g = throttle::LIN_U / -throttle::LIN_Y;
                let k = (th.p.y0 - 0.5) / g;
                let mut ex = ExcitationConfig::paper();
                ex.gain = k / (2.0 * ex.u_bar);
                ex.offset = -k / 2.0;
                ex.gain = -ex.gain;
                Plant {
                    name: "throttle-physical".into(),
                    dynamics: Dynamics::Throttle(th),
                    excitation: ex,
                }
            }
        }
    }

    /// The MIMO plant with its default excitation (the paper's family, one draw per input).
    pub fn mimo() -> Plant {
        let mut ex = ExcitationConfig::paper();
        ex.u_bar = MIMO_U_BAR;
        Plant {
            name: "mimo".into(),
            dynamics: Dynamics::Mimo(Box::default()),
            excitation: ex,
        }
    }

    pub fn output_names(&self) -> Vec<String> {
        match &self.dynamics {
            Dynamics::Throttle(_) => vec!["y".into()],
            Dynamics::Mimo(m) => m.model.outputs.iter().map(|o| o.name.clone()).collect(),
        }
    }

    pub fn input_names(&self) -> Vec<String> {
        match &self.dynamics {
            Dynamics::Throttle(_) => vec!["u".into()],
            Dynamics::Mimo(m) => m.model.inputs.clone(),
        }
    }

    /// True relative degree of each output.
    pub fn orders(&self) -> Vec<usize> {
        match &self.dynamics {
            Dynamics::Throttle(_) => vec![3],
            Dynamics::Mimo(m) => m.model.outputs.iter().map(|o| o.order).collect(),
        }
    }

    /// The true equations when they are polynomial (the throttle only at Patm = 0). `None` for the
    /// throttle at a nonzero ambient pressure.
    pub fn true_model(&self, tau: Option<f64>) -> Option<Model> {
        match &self.dynamics {
            Dynamics::Throttle(t) => t.true_model(tau),
            Dynamics::Mimo(m) => {
                let mut model = m.model.clone();
                model.tau = tau;
                Some(model)
            }
        }
    }

    /// The simulable system.
    pub fn system(&self) -> &(dyn System + Sync) {
        match &self.dynamics {
            Dynamics::Throttle(t) => t,
            Dynamics::Mimo(m) => &m.compiled,
        }
    }

    /// State at rest with zero input.
    pub fn rest_state(&self) -> Vec<f64> {
        match &self.dynamics {
            Dynamics::Throttle(t) => t.rest_state().to_vec(),
            Dynamics::Mimo(m) => vec![0.0; m.compiled.n_state()],
        }
    }

    /// Exact derivatives `0..=order+1` of every output: `[output][k]`. Panics when `x`, `u` or
    /// `du` is too short ([`Throttle::derivatives`], [`MimoPlant::derivatives`]).
    pub fn derivatives(&self, x: &[f64], u: &[f64], du: &[f64]) -> Vec<Vec<f64>> {
        match &self.dynamics {
            Dynamics::Throttle(t) => vec![t.derivatives(x, u[0], du[0]).to_vec()],
            Dynamics::Mimo(m) => m.derivatives(x, u, du),
        }
    }

    /// The excitation of run `run` under `seed` (one independent draw per input channel).
    pub fn excitation_for(&self, seed: u64, run: usize) -> ExcitationInput {
        let channels = (0..self.input_names().len())
            .map(|c| {
                self.excitation
                    .draw(&mut Rng::new(stream_seed(seed, run as u64, 1 + c as u64)))
            })
            .collect();
        ExcitationInput { channels }
    }
}

/// One generated run.
#[derive(Debug, Clone)]
pub struct Run {
    pub id: usize,
    pub t: Vec<f64>,
    /// `[input][sample]`
    pub u: Vec<Vec<f64>>,
    /// Measured outputs (with noise): `[output][sample]`.
    pub y: Vec<Vec<f64>>,
    /// Noise-free outputs: `[output][sample]`.
    pub y_true: Vec<Vec<f64>>,
    /// Exact derivatives: `[output][k][sample]`, k = 0..=order+1.
    pub derivatives: Vec<Vec<Vec<f64>>>,
    /// The excitation that drove the run.
    pub excitation: ExcitationInput,
}

/// Integration tolerances for the ground truth: well below any error identification can reach.
pub fn truth_options(run: usize) -> SimOptions {
    SimOptions {
        rtol: 1e-10,
        atol: 1e-10,
        run: run.to_string(),
        ..Default::default()
    }
}

/// Most samples (runs x samples per run) a generated dataset may have.
pub const MAX_DATASET_SAMPLES: usize = 1 << 30;

/// Generates `n_runs` runs of `n_samples` samples at `tau` from rest, with noise level `noise`
/// (the paper's eta, e.g. 0.03 for 3 %), deterministically from `seed`. Refuses a tau that
/// [`crate::records::check_tau`] refuses, an excitation that [`ExcitationConfig::check`] refuses,
/// no runs, more than [`MAX_DATASET_SAMPLES`] samples in all, fewer than 2 samples per run and a `noise`
/// that is negative or not finite; errs when a run's simulation fails.
pub fn dataset(
    plant: &Plant,
    n_runs: usize,
    n_samples: usize,
    tau: f64,
    noise: f64,
    seed: u64,
) -> Result<Vec<Run>> {
    crate::records::check_tau(tau)?;
    plant.excitation.check()?;
    if n_runs == 0 {
        return Err(Error::param("runs", "must be at least 1"));
    }
    // Each run holds its states and outputs: refuse sizes that cannot be allocated.
    if n_runs.saturating_mul(n_samples) > MAX_DATASET_SAMPLES {
        return Err(Error::TooLarge {
            what: format!("{n_runs} runs x {n_samples} samples"),
            needed_mib: (n_runs as f64) * (n_samples as f64) * 8.0 / 1048576.0,
            budget_mib: MAX_DATASET_SAMPLES as f64 * 8.0 / 1048576.0,
            hint: "generate fewer or shorter runs".into(),
        });
    }
    if n_samples < 2 {
        return Err(Error::param("n_samples", "need at least 2 samples per run"));
    }
    crate::util::finite_nonneg("noise", noise)?;
    let t: Vec<f64> = (0..n_samples).map(|k| k as f64 * tau).collect();
    let n_in = plant.input_names().len();
    let n_out = plant.output_names().len();
    (0..n_runs)
        .into_par_iter()
        .map(|r| {
            let ex = plant.excitation_for(seed, r);
            let x0 = plant.rest_state();
            let traj = simulate(plant.system(), &ex, &x0, &t, &truth_options(r))?;
            let mut u = vec![vec![0.0; n_samples]; n_in];
            let orders = plant.orders();
            let mut derivs: Vec<Vec<Vec<f64>>> = orders
                .iter()
                .map(|&n| vec![vec![0.0; n_samples]; n + 2])
                .collect();
            let (mut uk, mut duk) = (vec![0.0; n_in], vec![0.0; n_in]);
            for (k, &tk) in t.iter().enumerate() {
                ex.eval(tk, &mut uk);
                ex.derivative(tk, &mut duk);
                for c in 0..n_in {
                    u[c][k] = uk[c];
                }
                let d = plant.derivatives(traj.state_at(k), &uk, &duk);
                for (i, di) in d.iter().enumerate() {
                    for (j, v) in di.iter().enumerate() {
                        derivs[i][j][k] = *v;
                    }
                }
            }
            let y_true: Vec<Vec<f64>> = derivs.iter().map(|d| d[0].clone()).collect();
            let y = (0..n_out)
                .map(|i| {
                    noise::add_noise(
                        &y_true[i],
                        noise,
                        &mut Rng::new(stream_seed(seed, r as u64, 1000 + i as u64)),
                    )
                })
                .collect();
            Ok(Run {
                id: r,
                t: t.clone(),
                u,
                y,
                y_true,
                derivatives: derivs,
                excitation: ex,
            })
        })
        .collect()
}

/// Writes runs as CSV: `run, t, <inputs>, <outputs>` and, with `truth`, `<output>_true` and the
/// exact derivatives `<output>_dk_true` for k = 1..=order+1. Errs when the file cannot be created
/// or written. Panics when a run's input, output or (with `truth`) derivative series is shorter
/// than its `t`.
pub fn write_csv(plant: &Plant, runs: &[Run], path: &str, truth: bool) -> Result<()> {
    let io = |e: &dyn std::fmt::Display| Error::Io {
        path: path.into(),
        message: e.to_string(),
    };
    // Whole or not at all: a full disk or a kill half way leaves the file as it was.
    let file = crate::util::AtomicFile::create(std::path::Path::new(path))?;
    let mut w = csv::Writer::from_writer(file);
    let outs = plant.output_names();
    let mut header = vec!["run".to_string(), "t".to_string()];
    header.extend(plant.input_names());
    header.extend(outs.iter().cloned());
    if truth {
        for (i, o) in outs.iter().enumerate() {
            header.push(format!("{o}_true"));
            for k in 1..=plant.orders()[i] + 1 {
                header.push(format!("{o}_d{k}_true"));
            }
        }
    }
    w.write_record(&header).map_err(|e| io(&e))?;
    for r in runs {
        for k in 0..r.t.len() {
            let mut row = vec![r.id.to_string(), format!("{}", r.t[k])];
            row.extend(r.u.iter().map(|c| format!("{}", c[k])));
            row.extend(r.y.iter().map(|c| format!("{}", c[k])));
            if truth {
                for d in &r.derivatives {
                    row.extend(d.iter().map(|c| format!("{}", c[k])));
                }
            }
            w.write_record(&row).map_err(|e| io(&e))?;
        }
    }
    w.into_inner()
        .map_err(|e| io(&e.error().to_string()))?
        .commit()
}
