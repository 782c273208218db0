//! `discover` on the EMPS benchmark (a prismatic joint with friction) against a mass and viscous
//! friction nominal with the published M and Fv (see [`ctsid::discover::benchmarks::emps`]).
//! Prints the verdict, the Coulomb force read from the coefficient and the nominal mass
//! (published: 20.4 N), and the free-run RMS error on the pulses record in mm before and after.
//!
//! `cargo bench --bench emps_discover [-- DIR]`

use ctsid::discover::benchmarks::{emps, rms_after};
use ctsid::discover::discover;

fn main() {
    let dir = std::env::args()
        .filter(|a| a != "--bench")
        .nth(1)
        .unwrap_or_else(|| "../shared/data/emps".into());
    let s = match emps(&dir) {
        Ok(s) => s,
        Err(e) => return println!("skipped: {e}"),
    };
    let t0 = std::time::Instant::now();
    let d = discover(&s.records, &s.nominal, &s.options).unwrap();
    println!("{}", d.text());
    let test = &d.test_runs[0];
    println!(
        "EMPS pulses record, free-run RMS after {} samples: {:.2} mm nominal -> {:.2} mm {} ({:.1} s)",
        s.init_samples,
        1e3 * rms_after(d.nominal_model.as_ref().unwrap(), test, s.init_samples),
        1e3 * rms_after(d.final_model.as_ref().unwrap(), test, s.init_samples),
        d.verdict,
        t0.elapsed().as_secs_f64()
    );
}
