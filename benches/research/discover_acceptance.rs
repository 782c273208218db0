//! The acceptance matrix of `ctsid discover` on the generated cases: every case for seeds
//! 0..N (default 10) at 3 % noise, printing each verdict and the pass counts. The free-run
//! shrink is judged against the plant's noise-free output and printed against the measurement too.
//!
//! `cargo bench --bench discover_acceptance -- [SEEDS] [ETA] [CASE ...]`; `SCALE=s`
//! multiplies every case's excitation amplitude (default 1).

use ctsid::discover::cases::{generate_scaled, judge, options, CASES};
use ctsid::discover::discover;

fn main() {
    let args: Vec<String> = std::env::args()
        .filter(|a| a != "--bench")
        .skip(1)
        .collect();
    let seeds: u64 = args.first().and_then(|s| s.parse().ok()).unwrap_or(10);
    let eta: f64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(0.03);
    let chosen: Vec<String> = if args.len() > 2 {
        args[2..].to_vec()
    } else {
        CASES.iter().map(|s| s.to_string()).collect()
    };
    let scale: f64 = std::env::var("SCALE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let mut summary = Vec::new();
    for name in &chosen {
        let mut pass = 0;
        let mut ratios = Vec::new();
        let mut truth_ratios = Vec::new();
        // Largest time-invariance z among the named effects (the figure behind DRIFT_Z).
        let mut max_z = f64::NAN;
        for seed in 0..seeds {
            let t = std::time::Instant::now();
            let case = match generate_scaled(name, seed, eta, scale) {
                Ok(c) => c,
                Err(e) => {
                    println!("{name} seed {seed}: generation failed: {e}");
                    continue;
                }
            };
            let mut o = options(&case, seed);
            if let Ok(m) = std::env::var("HW") {
                o.half_width = m.parse().ok();
            }
            match discover(&case.records, &case.nominal, &o) {
                Ok(d) => {
                    let j = judge(&case, &d);
                    let (ok, why) = (j.pass, j.why);
                    if std::env::var("SHOW").is_ok() {
                        println!("{}", d.text());
                    }
                    pass += ok as usize;
                    ratios.push(d.nrmse_before / d.nrmse_after.max(1e-300));
                    truth_ratios.push(j.truth_ratio);
                    for e in &d.effects {
                        max_z = max_z.max(e.halves_z);
                    }
                    let extra = d
                        .closest
                        .clone()
                        .or_else(|| {
                            d.effects
                                .first()
                                .map(|e| format!("aliases {:?}", e.aliases))
                        })
                        .unwrap_or_default();
                    println!(
                        "{name} seed {seed}: {} {} m={} [{:.1} s] {why} | test {:.4} -> {:.4} | weak {:?} | {extra}",
                        if ok { "PASS" } else { "FAIL" },
                        d.verdict,
                        d.half_width,
                        t.elapsed().as_secs_f64(),
                        d.nrmse_before,
                        d.nrmse_after,
                        d.effects.iter().map(|e| e.weak_coefficient).collect::<Vec<_>>(),
                    );
                }
                Err(e) => println!("{name} seed {seed}: FAIL error {e}"),
            }
        }
        let med_min = |mut v: Vec<f64>| {
            v.sort_by(|a, b| a.total_cmp(b));
            (
                v.get(v.len() / 2).copied().unwrap_or(0.0),
                v.first().copied().unwrap_or(0.0),
            )
        };
        let (med, min) = med_min(ratios);
        let (tmed, tmin) = med_min(truth_ratios);
        summary.push(format!(
            "{name}: {pass}/{seeds} pass; test NRMSE before/after vs truth median {tmed:.2}x, min {tmin:.2}x; vs measurement median {med:.2}x, min {min:.2}x; named effects' largest over-time z {max_z:.1}"
        ));
    }
    println!("\n== acceptance at eta = {eta} ==");
    for s in summary {
        println!("{s}");
    }
}
