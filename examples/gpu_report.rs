//! GPU sweep report: correctness at full size and speed, for `benches/gpu_report.sh`.
//!
//! For each basis size it builds the GPU engine on seeded random Z (uniform in [-1, 1]), checks
//! one sweep against an exact f64 reference on a subset of candidates (|err| / sum_i |x_ij v_i|
//! < 1e-5, else the run fails), times sweeps, and prints a Markdown table: time per sweep, the
//! sweep time of a 200-step path (sweeps only: the active-set algebra on the CPU is extra), the
//! ratio to a CPU reference timed in the same run, and the fraction of the arithmetic limit.
//!
//! The CPU column is NOT the crate's CPU engine (crate::engine::cpu::CpuEngine, not on this
//! branch yet): it is a plain rayon f64 loop (`naive_f64_sweep`, one product of d factors per
//! pair), labelled as such in the output. Swap it for the CPU engine once merged.
//!
//! Usage: gpu_report [--samples N] [--sizes NZ:D,NZ:D,...] [--reps K] [--check K]
//!                   [--peak PAIRS_PER_S] [--require-real-gpu] [--cpu-max-pairs P]

use std::time::Instant;

use rayon::prelude::*;

use ctsid::basis::{Basis, BasisLimits, Code};
use ctsid::engine::gpu::{GpuEngine, GpuOptions};
use ctsid::engine::{Features, SweepEngine};

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f64 {
        2.0 * ((self.next() >> 11) as f64 / (1u64 << 53) as f64) - 1.0
    }
}

/// Plain rayon f64 reference: out_j = sum_i prod(z_i[vars of j]) * v_i, parallel over candidates.
fn naive_f64_sweep(
    rows: &[f64],
    n_z: usize,
    codes: &[Code],
    v: &[f64],
    out: &mut [f64],
    mag: Option<&mut [f64]>,
) {
    let one = |c: &Code| {
        let vars: Vec<usize> = c.vars().collect();
        let (mut s, mut m) = (0.0, 0.0);
        for (i, &vi) in v.iter().enumerate() {
            let z = &rows[i * n_z..(i + 1) * n_z];
            let t = vars.iter().fold(1.0, |a, &k| a * z[k]) * vi;
            s += t;
            m += t.abs();
        }
        (s, m)
    };
    match mag {
        Some(mag) => out
            .par_iter_mut()
            .zip(mag.par_iter_mut())
            .zip(codes.par_iter())
            .for_each(|((o, g), c)| {
                let (s, m) = one(c);
                *o = s;
                *g = m;
            }),
        None => out
            .par_iter_mut()
            .zip(codes.par_iter())
            .for_each(|(o, c)| *o = one(c).0),
    }
}

fn arg<T: std::str::FromStr>(args: &[String], name: &str, default: T) -> T {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n_s: usize = arg(&args, "--samples", 25_000);
    let sizes: String = arg(&args, "--sizes", "11:6,17:6,13:9".to_string());
    let reps: usize = arg(&args, "--reps", 20);
    let n_check: usize = arg(&args, "--check", 2000);
    // The H100 figure: 1.25e10 pairs in about 0.55 ms of f32 arithmetic.
    let peak: f64 = arg(&args, "--peak", 1.25e10 / 0.55e-3);
    let cpu_max_pairs: f64 = arg(&args, "--cpu-max-pairs", 2e10);
    let require_real = args.iter().any(|a| a == "--require-real-gpu");

    let mut rows_out = Vec::new();
    let mut failed = false;
    for spec in sizes.split(',') {
        let (n_z, d) = {
            let mut it = spec
                .split(':')
                .map(|x| x.trim().parse::<usize>().expect("--sizes takes NZ:D pairs"));
            (
                it.next().unwrap(),
                it.next().expect("--sizes takes NZ:D pairs"),
            )
        };
        let names: Vec<String> = (0..n_z).map(|k| format!("z{k}")).collect();
        let basis = Basis::new(&names, d, BasisLimits::default()).expect("basis");
        let n_c = basis.len();
        let mut rng = Rng(0xC7510 + n_z as u64 * 100 + d as u64);
        let cols: Vec<Vec<f64>> = (0..n_z)
            .map(|_| (0..n_s).map(|_| rng.uniform()).collect())
            .collect();
        let feats = Features::new(names.clone(), cols);
        let mut rows = vec![0.0; n_s * n_z];
        for k in 0..n_z {
            for i in 0..n_s {
                rows[i * n_z + k] = feats.column(k)[i];
            }
        }
        let v: Vec<f64> = (0..n_s).map(|_| rng.uniform()).collect();

        let t0 = Instant::now();
        let mut eng = match GpuEngine::new(
            &feats,
            &basis,
            GpuOptions {
                allow_cpu_adapter: !require_real,
                ..Default::default()
            },
        ) {
            Ok(e) => e,
            Err(e) => {
                eprintln!("gpu_report: {e}");
                std::process::exit(2);
            }
        };
        let setup = t0.elapsed().as_secs_f64();
        eprintln!(
            "# {} candidates (n_z={n_z}, d={d}): {}; layout {:?}",
            n_c,
            eng.describe(),
            eng.layout()
        );

        // Correctness on a spread subset (first, last, evenly spaced), every element checked.
        let mut out = vec![f64::NAN; n_c];
        let t1 = Instant::now();
        eng.sweep(&v, &mut out).expect("sweep");
        let first = t1.elapsed().as_secs_f64();
        let step = (n_c / n_check.max(1)).max(1);
        let mut idx: Vec<usize> = (0..n_c).step_by(step).collect();
        if *idx.last().unwrap() != n_c - 1 {
            idx.push(n_c - 1);
        }
        let sub: Vec<Code> = idx.iter().map(|&j| basis.code(j)).collect();
        let (mut want, mut mag) = (vec![0.0; sub.len()], vec![0.0; sub.len()]);
        naive_f64_sweep(&rows, n_z, &sub, &v, &mut want, Some(&mut mag));
        let mut worst = 0.0f64;
        for (k, &j) in idx.iter().enumerate() {
            let rel = if out[j].is_finite() {
                (out[j] - want[k]).abs() / mag[k].max(f64::MIN_POSITIVE)
            } else {
                f64::INFINITY
            };
            worst = worst.max(rel);
        }
        let ok = worst < 1e-5;
        failed |= !ok;

        // Timing: warm, then reps sweeps.
        let mut times = Vec::with_capacity(reps);
        for _ in 0..reps {
            let t = Instant::now();
            eng.sweep(&v, &mut out).expect("sweep");
            times.push(t.elapsed().as_secs_f64());
        }
        times.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let med = times[times.len() / 2];
        drop(eng);

        // CPU reference, same process, same data; extrapolated from a subset above cpu_max_pairs.
        let pairs = (n_s * n_c) as f64;
        let frac = (cpu_max_pairs / pairs).min(1.0);
        let m = ((n_c as f64 * frac).ceil() as usize).max(1);
        let cstep = (n_c / m).max(1);
        let csub: Vec<Code> = (0..n_c).step_by(cstep).map(|j| basis.code(j)).collect();
        let mut cout = vec![0.0; csub.len()];
        let t2 = Instant::now();
        naive_f64_sweep(&rows, n_z, &csub, &v, &mut cout, None);
        let cpu = t2.elapsed().as_secs_f64() * n_c as f64 / csub.len() as f64;
        let cpu_note = if csub.len() < n_c {
            " (extrapolated)"
        } else {
            ""
        };

        rows_out.push(format!(
            "| {n_s} x {n_c} (n_z={n_z}, d={d}) | {:.3} ms | {:.3} s | {:.1} ms{cpu_note} | {:.1}x | {:.1} % | {worst:.1e} {} | {:.2} s / {:.0} ms |",
            med * 1e3,
            200.0 * med,
            cpu * 1e3,
            cpu / med,
            100.0 * pairs / peak / med,
            if ok { "ok" } else { "FAIL" },
            setup,
            first * 1e3,
        ));
    }
    let threads = rayon::current_num_threads();
    println!("\nGPU sweep report ({} samples, median of {reps} sweeps; CPU column: naive rayon f64 loop on {threads} threads, NOT the crate's CPU engine)\n", n_s);
    println!("| problem | GPU per sweep | 200 sweeps (path, sweeps only) | CPU ref per sweep | ratio | of arithmetic limit ({:.2e} pairs/s) | max rel err vs f64 | setup / first sweep |", peak);
    println!("|---|---|---|---|---|---|---|---|");
    for r in rows_out {
        println!("{r}");
    }
    if failed {
        eprintln!("gpu_report: correctness check FAILED (max rel err >= 1e-5)");
        std::process::exit(1);
    }
}
