//! Diagnostic: the MIMO plant's output equations at fixed orders 3, 3, 3, a given degree and max
//! terms: `cargo bench --bench mimo_probe -- D MAX_TERMS [NOISE]` (`SEED=S` as `demo mimo --seed`;
//! `REFINE`, `NOSAME`, `LABELFILTER`, `NOWEIGHT` set switch the settings of the same names).
use ctsid::demo::records;
use ctsid::identify::{identify, Orders, Settings, Split};
use ctsid::plants::{dataset, Plant};
fn main() {
    let a: Vec<String> = std::env::args().filter(|a| a != "--bench").collect();
    let d: usize = a[1].parse().unwrap();
    let mt: usize = a[2].parse().unwrap();
    let eta: f64 = a.get(3).map(|s| s.parse().unwrap()).unwrap_or(0.0);
    let plant = Plant::mimo();
    // The configuration of `ctsid demo mimo`: 40 runs, 25 for training, 15 for the test.
    let seed: u64 = std::env::var("SEED").map_or(1, |s| s.parse().unwrap());
    let runs = dataset(&plant, 40, 1000, 0.01, eta, seed).unwrap();
    let rs = records(&runs, &plant.input_names(), &plant.output_names(), 0.01).unwrap();
    let ids: Vec<String> = (0..40).map(|i| i.to_string()).collect();
    let split = Split::new((0..25).collect(), None, (25..40).collect(), &ids).unwrap();
    let mut s = Settings::new(plant.output_names(), plant.input_names(), d);
    s.orders = Orders::Fixed(vec![3, 3, 3]);
    s.max_terms = mt;
    s.engine = ctsid::regression::EngineChoice::Cpu;
    s.refine = std::env::var("REFINE").is_ok();
    s.same_filter = std::env::var("NOSAME").is_err();
    s.label_filter = std::env::var("LABELFILTER").is_ok();
    s.weighting = std::env::var("NOWEIGHT").is_err();
    let t = std::time::Instant::now();
    let id = identify(&rs, &split, &s).unwrap();
    if let Some(r) = &id.refinement {
        println!("{}", r.message);
        println!("fit runs {:?}, gate runs {:?}", r.fit_runs, r.gate_runs);
        println!("train NRMSE {:?} -> {:?}", r.train_before, r.train_after);
        println!(
            "gate NRMSE {:?} -> {:?}",
            r.validation_before, r.validation_after
        );
        for (a, b) in r.derivative_fit.iter().zip(&r.refined) {
            println!("derivative fit: {a}\nrefined:        {b}");
        }
        for t in &r.completion {
            println!("completion: {t:?}");
        }
    }
    for o in &id.model.outputs {
        println!("{} terms: {}", o.terms.len(), o.to_text());
    }
    println!(
        "test NRMSE {:?}, {:.1} s",
        id.test_nrmse(),
        t.elapsed().as_secs_f64()
    );
    for o in 0..3 {
        let d = &id.derivatives[o][0];
        let tr = &runs[0].derivatives[o];
        let err: Vec<f64> = (0..4)
            .map(|k| {
                (100..900)
                    .map(|i| (d.values[k][i] - tr[k][i]).abs())
                    .fold(0.0, f64::max)
                    / tr[k].iter().map(|v| v.abs()).fold(0.0, f64::max)
            })
            .collect();
        println!(
            "output {o}: h {:.3} noise {:.2e} max rel err (interior) {:?}",
            d.h, d.noise_sd, err
        );
        let scale = tr[3].iter().map(|v| v.abs()).fold(0.0, f64::max);
        let head: Vec<String> = [0usize, 2, 4, 6, 8, 10, 15, 20, 30, 50]
            .iter()
            .map(|&i| format!("{}:{:.1e}", i, (d.values[3][i] - tr[3][i]).abs() / scale))
            .collect();
        println!(
            "   start errors of the third derivative: {}",
            head.join(" ")
        );
    }
}
