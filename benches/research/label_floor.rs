//! The trade-off of `identify::LABEL_FLOOR` (eBIC's residual floor in units of the label's own
//! uncertainty), measured at floors 0, 0.5, 0.7 and 1:
//! - the noise-free throttle (demo etc's data: 100 runs, 25 train), n = 3, d = 3: terms kept;
//! - the noise-free MIMO plant on 12 training runs (tests/identify_mimo.rs), d = 4: true terms
//!   found, extra terms, pooled free-run NRMSE against the truth per output;
//! - the MIMO plant at 1 % noise (demo mimo's data: 40 runs, 25 train), d = 3: the same.
//!
//! `cargo bench --bench label_floor [-- FLOOR,...]`
use ctsid::demo::{coefficient_errors, nrmse_vs_truth, records};
use ctsid::identify::{identify, Orders, Settings, Split};
use ctsid::model::Model;
use ctsid::plants::{dataset, Plant, Run, ThrottlePreset};
use ctsid::regression::EngineChoice;

/// Identifies `plant` on `runs` (the first `train` for training, the rest for testing) at
/// degree `d` with every output's order fixed at `order`.
fn fit(
    plant: &Plant,
    runs: &[Run],
    train: usize,
    order: usize,
    d: usize,
    floor: f64,
) -> ctsid::identify::Identification {
    let (inputs, outputs) = (plant.input_names(), plant.output_names());
    let rs = records(runs, &inputs, &outputs, runs[0].t[1] - runs[0].t[0]).unwrap();
    let ids: Vec<String> = (0..runs.len()).map(|i| i.to_string()).collect();
    let split = Split::new(
        (0..train).collect(),
        None,
        (train..runs.len()).collect(),
        &ids,
    )
    .unwrap();
    let mut s = Settings::new(outputs.clone(), inputs, d);
    s.orders = Orders::Fixed(vec![order; outputs.len()]);
    s.engine = EngineChoice::Cpu;
    s.label_floor = floor;
    identify(&rs, &split, &s).unwrap()
}

/// True terms found, extra terms and pooled free-run NRMSE vs truth (%), per output.
fn against_truth(id: &ctsid::identify::Identification, truth: &Model, runs: &[Run]) -> String {
    (0..truth.outputs.len())
        .map(|i| {
            let (rows, extra) = coefficient_errors(&id.model, truth, i);
            let found = rows.iter().filter(|r| r.2 != 0.0).count();
            let (_, _, pooled, diverged) = nrmse_vs_truth(id, runs, i);
            format!(
                "{found}/{} true, {} extra, NRMSE {:.2} %{}",
                rows.len(),
                extra.len(),
                100.0 * pooled,
                if diverged > 0 {
                    format!(" ({diverged} diverged)")
                } else {
                    String::new()
                }
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

fn main() {
    let floors: Vec<f64> = std::env::args()
        .filter(|a| a != "--bench")
        .nth(1)
        .map(|a| a.split(',').map(|v| v.parse().unwrap()).collect())
        .unwrap_or_else(|| vec![0.0, 0.5, 0.7, 1.0]);
    let throttle = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let throttle_runs = dataset(&throttle, 100, 1000, 0.003, 0.0, 1).unwrap();
    let mimo = Plant::mimo();
    let mimo_truth = mimo.true_model(Some(0.01)).unwrap();
    let clean = dataset(&mimo, 16, 1000, 0.01, 0.0, 7).unwrap();
    let noisy = dataset(&mimo, 40, 1000, 0.01, 0.01, 1).unwrap();
    for &floor in &floors {
        println!("floor {floor}:");
        let id = fit(&throttle, &throttle_runs, 25, 3, 3, floor);
        println!(
            "  throttle noise-free, n = 3, d = 3: {} terms",
            id.model.outputs[0].terms.len()
        );
        let id = fit(&mimo, &clean, 12, 3, 4, floor);
        println!(
            "  MIMO noise-free, 12 runs, d = 4: {}",
            against_truth(&id, &mimo_truth, &clean)
        );
        let id = fit(&mimo, &noisy, 25, 3, 3, floor);
        println!(
            "  MIMO 1 % noise, d = 3: {}",
            against_truth(&id, &mimo_truth, &noisy)
        );
    }
}
