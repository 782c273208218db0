//! `identify` on a measured benchmark record (../shared/data; skipped with a notice when absent):
//! Silverbox, the electronic Duffing oscillator. Trained on the multisine (4 runs, 2 for the
//! refinement gate), tested by free-run simulation of the full arrow.

use ctsid::discover::benchmarks::silverbox;
use ctsid::identify::{identify, Orders, Settings, Split};

#[test]
fn silverbox_identifies_the_duffing_form_and_simulates_the_arrow_near_1_mv() {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/silverbox/SNLS80mV.csv");
    if !p.exists() {
        eprintln!(
            "skipped: {} not found (the shared benchmark data is absent)",
            p.display()
        );
        return;
    }
    let s = silverbox(&p.to_string_lossy()).unwrap();
    let rs = &s.records;
    let ids: Vec<String> = rs.runs.iter().map(|r| r.id.clone()).collect();
    let split = Split::new(vec![0, 1, 2, 3], Some(vec![4, 5]), vec![6], &ids).unwrap();
    let mut settings = Settings::new(vec!["y".into()], vec!["u".into()], 3);
    settings.orders = Orders::Fixed(vec![2]);
    let id = identify(rs, &split, &settings).unwrap();
    let eq = &id.model.outputs[0];
    let text = eq.to_text();
    let coef = |name: &str| {
        eq.terms
            .iter()
            .find(|t| t.monomial() == name)
            .map(|t| t.coefficient)
    };
    // The cubic spring and the linear terms, with the signs of a stable hardening oscillator.
    assert!(coef("y^3").is_some_and(|c| c < 0.0), "{text}");
    assert!(coef("y").is_some_and(|c| c < 0.0), "{text}");
    assert!(coef("y_d1").is_some_and(|c| c < 0.0), "{text}");
    assert!(coef("u").is_some_and(|c| c > 0.0), "{text}");
    // Free-run RMS on the arrow after the 50 samples the benchmark gives for initialisation.
    let sim = &id.simulations[0];
    assert!(sim.error.is_none(), "{:?}", sim.error);
    let y = &rs.runs[6].channels[0];
    let e: Vec<f64> = sim.simulated[0][50..]
        .iter()
        .zip(&y[50..])
        .map(|(a, b)| a - b)
        .collect();
    let rms = (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
    eprintln!(
        "Silverbox arrow free-run RMS after 50 samples: {:.3} mV\n    {text}",
        1e3 * rms
    );
    // Measured 0.96 mV.
    assert!(rms < 1.2e-3, "arrow free-run RMS {rms} V\n{text}");
}
