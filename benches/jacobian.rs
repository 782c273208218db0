//! The refinement's Jacobian for one shooting segment (250 samples) of the throttle model
//! (n = 3, five coefficients): forward sensitivities through the Radau steps, as the refinement
//! computes it, against the forward differences of whole simulations it replaced (one base
//! simulation plus one per coefficient and initial state), measured side by side in the same
//! run. Also a nonlinear model (Duffing-like, two outputs), where the stage Jacobians change.
use criterion::{criterion_group, criterion_main, Criterion};
use ctsid::model::Model;
use ctsid::simulate::{simulate_model, simulate_model_sensitivities, SimOptions};

const THROTTLE: &str = r#"{"format": "ctsid-model/1", "inputs": ["u"], "outputs": [
    {"name": "y", "order": 3, "terms": [
        {"exponents": {}, "coefficient": 37664.0},
        {"exponents": {"y": 1}, "coefficient": -23978.0},
        {"exponents": {"y_d1": 1}, "coefficient": -32032.0},
        {"exponents": {"y_d2": 1}, "coefficient": -675.7},
        {"exponents": {"u": 1}, "coefficient": 1.222e6}]}]}"#;

/// Two outputs, nonlinear (Duffing-like with a cross term); shared with the simulator's
/// sensitivity test.
const NONLINEAR: &str = include_str!("../tests/data/models/coupled_oscillator.json");

fn bench_model(c: &mut Criterion, name: &str, text: &str, tau: f64, x0: &[f64]) {
    let mut model = Model::from_json_str(text, name).unwrap().compile().unwrap();
    let times: Vec<f64> = (0..250).map(|k| k as f64 * tau).collect();
    let u: Vec<Vec<f64>> = vec![times
        .iter()
        .map(|t| 0.02 * ((7.0 * t).sin() + 0.5 * (23.0 * t).sin()))
        .collect()];
    let opts = SimOptions {
        rtol: 1e-7,
        atol: 1e-9,
        ..Default::default()
    };
    let coefs: Vec<usize> = (0..model.coefficients().len()).collect();
    let mut g = c.benchmark_group(format!("jacobian {name}"));
    g.sample_size(20);
    g.bench_function("forward sensitivities", |b| {
        b.iter(|| simulate_model_sensitivities(&model, x0, &times, &u, &opts, &coefs).unwrap())
    });
    g.bench_function("forward differences", |b| {
        b.iter(|| {
            let base = model.coefficients();
            let mut out = vec![simulate_model(&model, x0, &times, &u, &opts).unwrap()];
            for k in 0..base.len() {
                let mut c = base.clone();
                c[k] *= 1.0 + 1e-5;
                model.set_coefficients(&c).unwrap();
                out.push(simulate_model(&model, x0, &times, &u, &opts).unwrap());
            }
            model.set_coefficients(&base).unwrap();
            for j in 0..x0.len() {
                let mut xp = x0.to_vec();
                xp[j] += 1e-5 * xp[j].abs().max(1e-3);
                out.push(simulate_model(&model, &xp, &times, &u, &opts).unwrap());
            }
            out
        })
    });
    g.finish();
}

fn bench(c: &mut Criterion) {
    bench_model(c, "throttle", THROTTLE, 0.003, &[1.6, 0.0, 0.0]);
    bench_model(c, "nonlinear", NONLINEAR, 0.01, &[0.3, -0.5, 0.1]);
}

criterion_group!(benches, bench);
criterion_main!(benches);
