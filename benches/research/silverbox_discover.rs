//! `discover` on the Silverbox benchmark (an electronic Duffing oscillator): a linear nominal
//! fitted on the training multisine, the full arrow as test run (see
//! [`ctsid::discover::benchmarks::silverbox`]). Prints the verdict and the arrow's free-run RMS
//! error in mV before and after (initial state from the first 50 samples, scored on the rest).
//!
//! `cargo bench --bench silverbox_discover [-- PATH/SNLS80mV.csv]`

use ctsid::discover::benchmarks::{rms_after, silverbox};
use ctsid::discover::discover;

fn main() {
    let path = std::env::args()
        .filter(|a| a != "--bench")
        .nth(1)
        .unwrap_or_else(|| "../shared/data/silverbox/SNLS80mV.csv".into());
    let s = match silverbox(&path) {
        Ok(s) => s,
        Err(e) => return println!("skipped: {e}"),
    };
    let t0 = std::time::Instant::now();
    let d = discover(&s.records, &s.nominal, &s.options).unwrap();
    println!("{}", d.text());
    let arrow = &d.test_runs[0];
    let before = rms_after(d.nominal_model.as_ref().unwrap(), arrow, s.init_samples);
    let after = rms_after(d.final_model.as_ref().unwrap(), arrow, s.init_samples);
    println!(
        "Silverbox arrow (full), free-run RMS after {} samples: {:.2} mV nominal -> {:.2} mV {} ({:.1} s)",
        s.init_samples,
        1e3 * before,
        1e3 * after,
        d.verdict,
        t0.elapsed().as_secs_f64()
    );
}
