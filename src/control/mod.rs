//! Feedback on an identified model: an observer of the derivatives and state feedback with
//! integral action, designed on the model and run around a plant.
//!
//! # Method
//! 1. *Operating point* ([`design::steady_input`]): the input `u*` that holds the model at rest
//!    at the setpoint r, the root of `P(r, 0, ..., 0, u) = 0` (damped Newton from several
//!    starts; a root where P hardly moves with u is refused).
//! 2. *Linearisation* there, from the model's exact Jacobians: the companion pair (A, B).
//! 3. *Pole placement* (Ackermann) in time scaled by the bandwidth w, with states
//!    `y^(k) / w^k`: a throttle's companion row holds 1e6 beside 1, and the scaled matrices are
//!    of order one. The n state gains and one integral gain put the integrator's pole and every
//!    open-loop pole no faster than w at -w, keep faster stable ones, and move faster unstable
//!    or lightly damped ones to minus their magnitude ([`design::placed_poles`]); the setpoint
//!    enters through the integrator only (the loop starts bumpless), so the designed step
//!    response has no zeros and, with real poles, no overshoot ([`designed_response`]). The
//!    observer's n gains put its poles at -f w (f = 3 by default), or keep an open-loop pole
//!    that is faster. The placement is checked by Cayley-Hamilton in the scaled units. Pole
//!    placement rather than LQR: the bandwidth is the one number an engineer specifies first,
//!    and it fixes every pole.
//! 4. *The loop* ([`closed_loop::run`]): a digital controller sampled at tau, as it would run on
//!    the machine. Each sample it reads the output, updates the integral of the error, and holds
//!    `u = u* - K (x_hat - x*) - k_i q` until the next sample; the observer integrates the
//!    *nonlinear* model corrected by its gain towards the held measurement, together with the
//!    plant, by the crate's stiff integrator. Any [`crate::simulate::System`] can be the plant:
//!    the model itself (the design check), another model, or a built-in plant with known truth
//!    (whether a design on the identified model works on the real thing). Input limits clip u;
//!    while clipped, the integrator takes only what pulls u back inside (no wind-up, no stall).
//!
//! # Assumptions
//! One output and one input; the input enters the model's highest derivative (relative degree n,
//! as every ctsid model is written); the poles the design moves are slow against the sampling
//! (`p tau <= 0.5`, checked). A model identified at a few operating points is trusted near
//! them: the integral action removes a steady error the model does not predict, not a wrong
//! sign of the gain.

pub mod closed_loop;
pub mod design;
pub mod tracking;

pub use closed_loop::{
    check_block, check_duration, check_scenario, default_duration, designed_response, metrics,
    model_at_rest, rest_state, run, step_plot, track, Plant, Scenario, StepMetrics, Trace,
    MAX_SAMPLES,
};
pub use design::{design, steady_input, with_chain_observer, DesignOptions};
pub use tracking::{
    chain_observer_gains, tracking_metrics, Law, ProfileLaw, Reference, Tracking, TrackingMetrics,
};

use crate::model::Model;
use nalgebra::{DMatrix, DVector};

/// A controller designed on a model (see the module docs).
#[derive(Debug, Clone)]
pub struct Design {
    pub output: String,
    pub input: String,
    pub order: usize,
    pub setpoint: f64,
    /// Steady input at the setpoint.
    pub u_star: f64,
    /// Sampling period of the controller.
    pub tau: f64,
    /// Linearisation at the setpoint: `x' = A (x - x*) + B (u - u*)`, x = (y, ..., y^(n-1)).
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    /// Eigenvalues (re, im) of A.
    pub open_loop: Vec<(f64, f64)>,
    /// Controller poles at -bandwidth (rad/s); observer poles at -observer_speed * bandwidth.
    pub bandwidth: f64,
    pub observer_speed: f64,
    /// State gains (on y, ..., y^(n-1)) and the gain on the integral of y - r.
    pub k: Vec<f64>,
    pub k_i: f64,
    /// Observer gains (on y - y_hat, into each estimated derivative).
    pub l: Vec<f64>,
    /// Eigenvalues of the linear closed loop (n + 1) and of the observer error (n), from the
    /// gains: they check the placement.
    pub closed_loop: Vec<(f64, f64)>,
    pub observer: Vec<(f64, f64)>,
    /// The model the observer runs.
    pub model: Model,
    /// What the design changed in the model's linearisation, and why (a sign smoothing's
    /// slope left out; see [`design::design`]).
    pub notes: Vec<String>,
}

/// `a+bi` lists for reports.
pub fn format_poles(p: &[(f64, f64)]) -> String {
    p.iter()
        .map(|(r, i)| {
            // A multiple pole comes out of the eigensolver split into a faint pair (by about
            // eps^(1/k) of its size: 1e-8 for a double pole, 1e-5 for a triple one).
            if i.abs() <= 1e-4 * r.abs().max(1e-300) {
                crate::util::num4(*r)
            } else {
                let sign = if *i < 0.0 { '-' } else { '+' };
                format!(
                    "{}{sign}{}i",
                    crate::util::num4(*r),
                    crate::util::num4(i.abs())
                )
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}
