//! The smoother level of the derivative blend and the window it is judged over
//! (`DerivativeOptions::smooth_window`, default 6): trimmed p95 on the shared signals at 0 (no
//! smoother level), 2 and 6, and the rows that meet every gate of the derivative issue.
//!
//! `cargo bench --bench derivative_windows [-- SIGNALS_DIR]` (default: the repository's
//! copy, tests/data/signals, identical to ../shared/signals)
use ctsid::derivatives::benchmark::{gates_pass, run_with};
use ctsid::derivatives::DerivativeOptions;
use std::path::PathBuf;

fn main() {
    let dir = std::env::args()
        .filter(|a| a != "--bench")
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/signals"))
        });
    let settings = [0.0, 2.0, 6.0];
    let results: Vec<_> = settings
        .iter()
        .map(|&w| {
            let o = DerivativeOptions {
                smooth_window: w,
                ..Default::default()
            };
            run_with(&dir, &o).expect("the shared signals")
        })
        .collect();
    println!("trimmed p95, orders 1/2/3/4, at smooth_window 0 | 2 | 6");
    for (i, r) in results[0].iter().enumerate() {
        let cells: Vec<String> = results
            .iter()
            .map(|rows| {
                let t = rows[i].trimmed_p95;
                format!("{:.3}/{:.3}/{:.3}/{:.3}", t[0], t[1], t[2], t[3])
            })
            .collect();
        println!("{:15} {}%: {}", r.signal, r.noise, cells.join(" | "));
    }
    for (w, rows) in settings.iter().zip(&results) {
        let pass = rows.iter().filter(|r| gates_pass(r)).count();
        println!(
            "smooth_window {w}: {pass} of {} rows meet every gate",
            rows.len()
        );
    }
}
