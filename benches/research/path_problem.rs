//! The seeded problem of `gpu_report`'s paths, shared with `f32_paths`: Z uniform in [-1, 1],
//! a swept vector, and a label of six random monomials plus 1 % noise, drawn in that order
//! from one generator per shape (so both reports see the same problem); and their option
//! reader.

use ctsid::basis::Basis;
use ctsid::engine::Features;
use ctsid::plants::rng::Rng;
use ctsid::regression::{Method, PathOptions};

pub struct Problem {
    /// The generator after Z and v were drawn (the label comes next).
    pub rng: Rng,
    pub feats: Features,
    /// A vector to sweep (`gpu_report` times its sweeps; `f32_paths` runs paths only).
    #[allow(dead_code)]
    pub v: Vec<f64>,
}

impl Problem {
    pub fn new(n_z: usize, d: usize, n_s: usize) -> Problem {
        let mut rng = Rng::new(0xC7510 + n_z as u64 * 100 + d as u64);
        let names: Vec<String> = (0..n_z).map(|k| format!("z{k}")).collect();
        let cols: Vec<Vec<f64>> = (0..n_z)
            .map(|_| (0..n_s).map(|_| rng.uniform_in(-1.0, 1.0)).collect())
            .collect();
        let feats = Features::new(names, cols).unwrap();
        let v: Vec<f64> = (0..n_s).map(|_| rng.uniform_in(-1.0, 1.0)).collect();
        Problem { rng, feats, v }
    }
}

/// Six random monomials of the basis with coefficients of either sign, plus 1 % noise.
pub fn label(rng: &mut Rng, basis: &Basis, f: &Features) -> Vec<f64> {
    let n = f.n_samples;
    let mut y = vec![0.0; n];
    for t in 0..6 {
        let j = 1 + (rng.next_u64() % (basis.len() as u64 - 1)) as usize;
        let c = if t % 2 == 0 { 1.0 } else { -1.5 };
        let code = basis.code(j);
        let mut col = vec![c; n];
        for k in code.vars() {
            col.iter_mut().zip(f.column(k)).for_each(|(a, z)| *a *= z);
        }
        y.iter_mut().zip(&col).for_each(|(a, b)| *a += b);
    }
    let sd = (y.iter().map(|x| x * x).sum::<f64>() / n as f64)
        .sqrt()
        .max(1e-12);
    for yi in &mut y {
        *yi += 0.01 * sd * rng.uniform_in(-1.0, 1.0);
    }
    y
}

/// The value after `name` in `args`, or `default` when it is missing or does not parse.
pub fn arg<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// The paths both reports run: LassoLars, at most `steps` steps and terms.
pub fn path_options(steps: usize) -> PathOptions {
    PathOptions {
        method: Method::LassoLars,
        max_terms: steps,
        max_steps: steps,
        ..PathOptions::default()
    }
}
