//! The CPU engine's f32 and f64 paths on `gpu_report`'s problems: where their active sets part.
//!
//! `docs/gpu.md` found the GPU path's active set leaving the CPU f64 path's at step 91 / 94 of
//! the 12,376 / 100,947-candidate problems (a six-term truth at 1 % noise, deep in the noise by
//! then). Whether f32 sweeps alone do that is a CPU question: this runs both precisions of the
//! CPU engine on the same problems (LassoLars, as `gpu_report`) and prints the first step at
//! which the active sets differ, and how far apart the two paths' coefficients are before it.
//!
//! Usage: `cargo bench --bench f32_paths -- [--sizes NZ:D,...] [--samples N] [--steps N]`.

use ctsid::basis::{Basis, BasisLimits};
use ctsid::engine::{CpuEngine, CpuOptions, Precision};
use ctsid::regression::{lars_path, Path};

#[path = "path_problem.rs"]
mod problem;

fn main() {
    let args: Vec<String> = std::env::args().filter(|a| a != "--bench").collect();
    let n_s: usize = problem::arg(&args, "--samples", 25_000);
    let steps: usize = problem::arg(&args, "--steps", 200);
    let sizes: String = problem::arg(&args, "--sizes", "11:6,17:6".to_string());
    println!("| problem | f32 path | f64 path | active sets first differ | largest coefficient difference before it (relative) |");
    println!("|---|---|---|---|---|");
    for spec in sizes.split(',') {
        let mut it = spec
            .split(':')
            .map(|x| x.trim().parse::<usize>().expect("NZ:D"));
        let (n_z, d) = (it.next().expect("NZ:D"), it.next().expect("NZ:D"));
        let names: Vec<String> = (0..n_z).map(|k| format!("z{k}")).collect();
        let basis = Basis::new(&names, d, BasisLimits::default()).expect("basis");
        let problem::Problem { mut rng, feats, .. } = problem::Problem::new(n_z, d, n_s);
        let y = problem::label(&mut rng, &basis, &feats);
        let opts = problem::path_options(steps);
        let run = |precision| {
            let mut e = CpuEngine::new(
                &basis,
                &feats,
                CpuOptions {
                    precision,
                    materialize_limit_bytes: 0,
                },
            )
            .expect("engine");
            let t = std::time::Instant::now();
            let p = lars_path(&mut e, &y, None, &opts).expect("path");
            (p, t.elapsed().as_secs_f64())
        };
        let (p32, t32) = run(Precision::F32);
        let (p64, t64) = run(Precision::F64);
        let k = (p32.breakpoints.len()).min(p64.breakpoints.len()) - 1;
        let first = (1..=k).find(|&s| p32.breakpoints[s].active != p64.breakpoints[s].active);
        let upto = first.map_or(k, |s| s - 1);
        println!(
            "| {n_s} x {} (n_z={n_z}, d={d}) | {} steps ({:?}), {t32:.1} s | {} steps ({:?}), {t64:.1} s | {} | {:.1e} |",
            basis.len(),
            p32.breakpoints.len() - 1,
            p32.stop,
            p64.breakpoints.len() - 1,
            p64.stop,
            first.map_or(format!("same over {k} steps"), |s| format!("step {s}")),
            worst_coefficient_gap(&p32, &p64, upto),
        );
    }
}

/// The largest `|b32 - b64| / max |b64|` over the breakpoints 1..=upto (same active sets).
fn worst_coefficient_gap(a: &Path, b: &Path, upto: usize) -> f64 {
    (1..=upto)
        .map(|s| {
            let (x, y) = (&a.breakpoints[s].coefs, &b.breakpoints[s].coefs);
            let scale = y
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()))
                .max(f64::MIN_POSITIVE);
            x.iter()
                .zip(y)
                .map(|(p, q)| (p - q).abs() / scale)
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}
