//! A MIMO plant of the paper's size with known polynomial truth.
//!
//! Two inputs, three outputs of relative degree 3 each, so the features of every output are the
//! 9 derivatives `y_j, y_j', y_j''` plus the 2 inputs (dim z = 11; degree 6 gives C(17, 6) =
//! 12,376 candidates per output). Each output has a stable linear chain (poles -1, -2, -3;
//! -1, -2, -4; -1, -2, -5) plus a few degree-2 and degree-3 coupling terms:
//! ```text
//! y1''' = -6 y1 - 11 y1' - 6 y1'' + 18 u1 + 2 y2 y3 - 0.3 y1^3
//! y2''' = -8 y2 - 14 y2' - 7 y2'' + 24 u2 + 2 y1 y3'
//! y3''' = -10 y3 - 17 y3' - 8 y3'' + 15 u1 - 12 u2 + y1^2 - y2 y2' u1
//! ```
//! The input gains put the outputs at order one (unit DC gain from u1 to y1 and from u2 to y2)
//! and the coupling coefficients make each coupling term carry a few to ten percent of the RMS
//! of its right-hand side under the default excitation: large enough to be found, small enough
//! to stay stable (the cubic destabilises y1 only beyond |y1| = 8.2; the outputs stay near 3 at
//! most over 100 runs).
//! The plant *is* this polynomial model, simulated with the same compiled evaluator as
//! identified models. Its default excitation is the paper's family (u_bar = 5, mu = 4,
//! w_max = 10, n_B = 20) drawn independently for each input.

use crate::model::{CompiledModel, Model, OutputEquation, Term};

/// The MIMO plant.
#[derive(Debug, Clone)]
pub struct MimoPlant {
    pub model: Model,
    pub compiled: CompiledModel,
}

impl Default for MimoPlant {
    fn default() -> Self {
        Self::new()
    }
}

impl MimoPlant {
    pub fn new() -> MimoPlant {
        let t = Term::new;
        let model = Model::new(
            &["u1", "u2"],
            vec![
                OutputEquation::new(
                    "y1",
                    3,
                    vec![
                        t(&[("y1", 1)], -6.0),
                        t(&[("y1_d1", 1)], -11.0),
                        t(&[("y1_d2", 1)], -6.0),
                        t(&[("u1", 1)], 18.0),
                        t(&[("y2", 1), ("y3", 1)], 2.0),
                        t(&[("y1", 3)], -0.3),
                    ],
                ),
                OutputEquation::new(
                    "y2",
                    3,
                    vec![
                        t(&[("y2", 1)], -8.0),
                        t(&[("y2_d1", 1)], -14.0),
                        t(&[("y2_d2", 1)], -7.0),
                        t(&[("u2", 1)], 24.0),
                        t(&[("y1", 1), ("y3_d1", 1)], 2.0),
                    ],
                ),
                OutputEquation::new(
                    "y3",
                    3,
                    vec![
                        t(&[("y3", 1)], -10.0),
                        t(&[("y3_d1", 1)], -17.0),
                        t(&[("y3_d2", 1)], -8.0),
                        t(&[("u1", 1)], 15.0),
                        t(&[("u2", 1)], -12.0),
                        t(&[("y1", 2)], 1.0),
                        t(&[("y2", 1), ("y2_d1", 1), ("u1", 1)], -1.0),
                    ],
                ),
            ],
            None,
        );
        let compiled = model.compile().expect("the built-in MIMO model is valid");
        MimoPlant { model, compiled }
    }

    /// Derivatives `0..=4` of each output at state `x`, input `u`, input rate `du`:
    /// `[output][k]`. Orders 0..2 are states, 3 is the polynomial, 4 its time derivative.
    /// Panics when `x` is shorter than the state, `x` and `u` together are longer than the state
    /// and inputs, or `du` is shorter than `u`.
    pub fn derivatives(&self, x: &[f64], u: &[f64], du: &[f64]) -> Vec<Vec<f64>> {
        let c = &self.compiled;
        let n = c.n_state();
        let mut z = x.to_vec();
        z.extend_from_slice(u);
        let mut dx = vec![0.0; n];
        c.rhs_unchecked(x, u, &mut dx);
        let mut g = vec![0.0; n + u.len()];
        (0..c.n_outputs())
            .map(|i| {
                let o = c.offset(i);
                let ord = c.orders()[i];
                let mut d: Vec<f64> = x[o..o + ord].to_vec();
                d.push(dx[o + ord - 1]);
                c.grad_output_unchecked(i, &z, &mut g);
                let rate: f64 = (0..n).map(|k| g[k] * dx[k]).sum::<f64>()
                    + (0..u.len()).map(|k| g[n + k] * du[k]).sum::<f64>();
                d.push(rate);
                d
            })
            .collect()
    }
}
