//! Issue 6's stretch case: the throttle (Patm = 0, the paper's excitation, 3 % noise) with a
//! hidden Coulomb friction torque `Fc tanh(y' / 1e-3)` on the plate, against the true linear
//! third-order nominal. The friction acts on the angular velocity `y_d1`, but it reaches the
//! output equation `y''' = ...` through the electrical dynamics (a step `-(R/L) Fc / J sign(y')`
//! plus impulses at every reversal), and the built-in dictionary's velocity for a third-order
//! model is `y_d2`; so the run adds the user effect `sign(y_d1)` and prints what the workflow
//! finds.
//!
//! `cargo bench --bench etc_friction_discover [-- FC_OVER_J]` (default 20 rad/s^2)

use ctsid::discover::{discover, Options};
use ctsid::plants::noise::add_noise;
use ctsid::plants::rng::{stream_seed, Rng};
use ctsid::plants::throttle::{Throttle, ThrottleParams};
use ctsid::plants::{truth_options, Plant, ThrottlePreset};
use ctsid::records::{RecordSet, Run};
use ctsid::simulate::{simulate, Input, System};

struct WithFriction {
    t: Throttle,
    fc: f64,
}

impl System for WithFriction {
    fn dim(&self) -> usize {
        3
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.t.rhs(x, u, dx);
        dx[1] -= self.fc / self.t.p.j * (x[1] / 1e-3).tanh();
    }
}

fn main() {
    let fc_over_j: f64 = std::env::args()
        .filter(|a| a != "--bench")
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(20.0);
    let p = ThrottleParams::paper(0.0);
    let sys = WithFriction {
        t: Throttle::new(p),
        fc: fc_over_j * p.j,
    };
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let (tau, n) = (0.003, 1000);
    let times: Vec<f64> = (0..n).map(|k| k as f64 * tau).collect();
    let mut runs = Vec::new();
    for r in 0..12usize {
        let ex = plant.excitation_for(7, r);
        let x0 = sys.t.rest_state();
        let tr = simulate(&sys, &ex, &x0, &times, &truth_options(r)).expect("truth simulates");
        let y_true = tr.series(0).unwrap();
        let y = add_noise(&y_true, 0.03, &mut Rng::new(stream_seed(7, r as u64, 1000)));
        let mut uk = [0.0];
        let u: Vec<f64> = times
            .iter()
            .map(|&t| {
                ex.eval(t, &mut uk);
                uk[0]
            })
            .collect();
        runs.push(Run {
            id: r.to_string(),
            channels: vec![y, u],
            t0: 0.0,
            rows: (0..n).collect(),
        });
    }
    let rs = RecordSet::new(tau, vec!["y".into(), "u".into()], runs).unwrap();
    let nominal = plant.true_model(Some(tau)).unwrap();
    let mut o = Options::new((0..6).collect(), vec![6, 7, 8], vec![9, 10, 11]);
    o.user_effects
        .push(("coulomb_friction".into(), "sign(y_d1)".into()));
    let t0 = std::time::Instant::now();
    let d = discover(&rs, &nominal, &o).unwrap();
    println!("{}", d.text());
    let expected = -p.r / p.l * fc_over_j;
    println!(
        "ETC with hidden Coulomb torque (Fc/J = {fc_over_j} rad/s^2; in y''' a step of (R/L) Fc/J = {:.4e} times -sign(y_d1)): verdict {}, test NRMSE {:.4} -> {:.4} ({:.1} s)",
        -expected,
        d.verdict,
        d.nrmse_before,
        d.nrmse_after,
        t0.elapsed().as_secs_f64()
    );
}
