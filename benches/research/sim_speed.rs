//! The simulator's speed on a benchmark's model file: the model simulated over the benchmark's
//! test run from its first sample at the fitting tolerances (`SimOptions::fitting`, what
//! refinement and the gates use), plain and with the sensitivities of every coefficient (what
//! each refinement iteration runs), best of five, with steps per sample and a checksum of the
//! trajectory (to see that a change kept the same bits).
//!
//! `cargo bench --bench sim_speed -- NAME MODEL.json` (a model file from `ctsid benchmark NAME`)
use ctsid::benchmark::load;
use ctsid::simulate::{run_data, simulate_model, simulate_model_sensitivities, SimOptions};
use ctsid::Model;

fn main() {
    let args: Vec<String> = std::env::args().filter(|a| a != "--bench").collect();
    let (Some(name), Some(path)) = (args.get(1), args.get(2)) else {
        return println!("usage: sim_speed NAME MODEL.json");
    };
    let model = Model::read(path).unwrap();
    let b = match load(name, "../shared/data") {
        Ok(b) => b,
        Err(e) => return println!("skipped: {e}"),
    };
    let compiled = model.compile().unwrap();
    let test = run_data(&model, &b.records, &b.records.runs[b.split.test[0]]).unwrap();
    let mut x0 = vec![0.0; compiled.n_state()];
    x0[0] = test.y[0][0];
    let o = SimOptions::fitting();
    let n = test.t.len() as f64;
    let coefs: Vec<usize> = (0..compiled.coefficients().len()).collect();
    let best = |f: &dyn Fn() -> (f64, usize)| {
        (0..5)
            .map(|_| {
                let clock = std::time::Instant::now();
                let (sum, steps) = f();
                (clock.elapsed().as_secs_f64(), sum, steps)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap()
    };
    let plain = best(&|| {
        let tr = simulate_model(&compiled, &x0, &test.t, &test.u, &o).unwrap();
        (tr.x.iter().sum(), tr.steps)
    });
    let sens = best(&|| {
        let (tr, s) =
            simulate_model_sensitivities(&compiled, &x0, &test.t, &test.u, &o, &coefs).unwrap();
        (tr.x.iter().chain(&s).sum(), tr.steps)
    });
    for (label, (secs, sum, steps)) in [("plain", plain), ("sensitivities", sens)] {
        println!(
            "{label}: {:.1} us per sample, {:.2} steps per sample, checksum {sum:e}",
            1e6 * secs / n,
            steps as f64 / n
        );
    }
}
