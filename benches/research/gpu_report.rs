//! GPU sweep report: correctness at full size and speed, for `benches/gpu_report.sh`.
//!
//! For each basis size it builds the GPU engine on seeded random Z (uniform in [-1, 1]), checks
//! one sweep against an exact f64 reference on a subset of candidates (|err| / sum_i |x_ij v_i|
//! < 1e-5, else the run fails), times sweeps, and prints a Markdown table: time per sweep, the
//! sweep time of a 200-step path (sweeps only: the active-set algebra on the CPU is extra), the
//! ratio to a CPU reference timed in the same run, and the fraction of the arithmetic limit.
//!
//! The CPU columns are the crate's CPU engine ([`CpuEngine`], matrix-free, f32 and f64 products,
//! f64 sums) on the same data in the same process, so the ratios compare engines on one machine.
//! The path columns run `lars_path` (LassoLars, at most 200 steps and 200 terms) on a sparse
//! polynomial label plus noise, per engine, active-set algebra included. A CPU path whose
//! estimated time exceeds `--cpu-path-budget` seconds is cut short and its time per step
//! extrapolated to 200 steps (marked "extrap."); the GPU path's entering order is compared with
//! the CPU f64 path's over the steps both ran.
//!
//! With `--shapes WGxR:FDs,...` it first times the sweep for each kernel shape (workgroup size,
//! candidates per invocation, largest factor degree, `s` scalar or `a` array code; see
//! `KernelShape`), each checked like the default; `--shapes-only` stops there.
//!
//! Usage: gpu_report [--samples N] [--sizes NZ:D,NZ:D,...] [--reps K] [--check K]
//!                   [--peak PAIRS_PER_S] [--require-real-gpu] [--cpu-max-pairs P]
//!                   [--cpu-path-budget S] [--steps N] [--no-bounds-checks]
//!                   [--shapes WGxR:FDs[/CHUNK],...] [--shapes-only] [--shape WGxR:FDs[/CHUNK]]
//!
//! `--shape` sets the kernel shape of the main report (default: `KernelShape::default()`).

use std::time::Instant;

#[path = "path_problem.rs"]
mod problem;

use rayon::prelude::*;

use ctsid::basis::{Basis, BasisLimits, Code};
use ctsid::engine::gpu::{GpuEngine, GpuOptions, KernelShape};
use ctsid::engine::{CpuEngine, CpuOptions, Precision, SweepEngine};
use ctsid::regression::{lars_path, PathOptions};

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

use problem::arg;

fn main() {
    let args: Vec<String> = std::env::args().filter(|a| a != "--bench").collect();
    let n_s: usize = arg(&args, "--samples", 25_000);
    let sizes: String = arg(&args, "--sizes", "11:6,17:6,13:9".to_string());
    let reps: usize = arg(&args, "--reps", 20);
    let n_check: usize = arg(&args, "--check", 2000);
    // The H100 figure: 1.25e10 pairs in about 0.55 ms of f32 arithmetic.
    let peak: f64 = arg(&args, "--peak", 1.25e10 / 0.55e-3);
    // Above this many pairs a CPU sweep is timed once (it takes seconds).
    let cpu_max_pairs: f64 = arg(&args, "--cpu-max-pairs", 2e9);
    let require_real = args.iter().any(|a| a == "--require-real-gpu");
    let cpu_path_budget: f64 = arg(&args, "--cpu-path-budget", 60.0);
    let steps: usize = arg(&args, "--steps", 200);
    let shapes: Vec<KernelShape> = arg(&args, "--shapes", String::new())
        .split(',')
        .filter(|x| !x.is_empty())
        .map(|x| parse_shape(x).unwrap_or_else(|| panic!("--shapes: cannot read {x:?}")))
        .collect();
    let shapes_only = args.iter().any(|a| a == "--shapes-only");
    let main_shape = match arg(&args, "--shape", String::new()).as_str() {
        "" => KernelShape::default(),
        x => parse_shape(x).unwrap_or_else(|| panic!("--shape: cannot read {x:?}")),
    };
    let options = |kernel: KernelShape| GpuOptions {
        allow_cpu_adapter: !require_real,
        bounds_checks: !args.iter().any(|a| a == "--no-bounds-checks"),
        kernel,
        ..Default::default()
    };
    let mut shape_rows = Vec::new();

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
        let problem::Problem { mut rng, feats, v } = problem::Problem::new(n_z, d, n_s);
        let mut rows = vec![0.0; n_s * n_z];
        for k in 0..n_z {
            for i in 0..n_s {
                rows[i * n_z + k] = feats.column(k)[i];
            }
        }
        let pairs = (n_s * n_c) as f64;

        for shape in &shapes {
            let mut eng = match GpuEngine::new(&feats, &basis, options(*shape)) {
                Ok(e) => e,
                Err(e) => {
                    shape_rows.push(format!("| {n_s} x {n_c} | {shape:?} | refused: {e} |||"));
                    continue;
                }
            };
            let mut out = vec![f64::NAN; n_c];
            eng.sweep(&v, &mut out).expect("sweep");
            let worst = worst_error(&out, &rows, n_z, &basis, &v, n_check);
            failed |= worst >= 1e-5;
            let med = median_time(reps, || eng.sweep(&v, &mut out).expect("sweep"));
            let l = eng.layout();
            shape_rows.push(format!(
                "| {n_s} x {n_c} (n_z={n_z}, d={d}) | {}x{} FD {} (table {}, chunk {}, {} blocks) {} | {:.3} ms | {:.2e} | {worst:.1e} |",
                shape.workgroup,
                shape.per_invocation,
                l.factor_degree,
                l.table_len,
                l.chunk,
                l.n_blocks,
                if shape.scalar_code { "scalar" } else { "array" },
                med * 1e3,
                pairs / med,
            ));
            eprintln!("{}", shape_rows.last().unwrap());
        }
        if shapes_only {
            continue;
        }

        let t0 = Instant::now();
        let mut eng = match GpuEngine::new(&feats, &basis, options(main_shape)) {
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

        let mut out = vec![f64::NAN; n_c];
        let t1 = Instant::now();
        eng.sweep(&v, &mut out).expect("sweep");
        let first = t1.elapsed().as_secs_f64();
        let worst = worst_error(&out, &rows, n_z, &basis, &v, n_check);
        let ok = worst < 1e-5;
        failed |= !ok;

        // Timing: warm, then reps sweeps.
        let med = median_time(reps, || eng.sweep(&v, &mut out).expect("sweep"));

        // A label with a sparse polynomial truth plus noise, for the paths.
        let y = problem::label(&mut rng, &basis, &feats);
        let path_opts = problem::path_options(steps);
        let t = Instant::now();
        let gpu_path = lars_path(&mut eng, &y, None, &path_opts).expect("gpu path");
        let gpu_path_s = t.elapsed().as_secs_f64();
        let gpu_steps = gpu_path.breakpoints.len() - 1;
        drop(eng);

        // The CPU engine, f32 and f64, same data, same process.
        let mut cpu_cells = Vec::new();
        let mut order_ok = String::from("-");
        let mut f32_path = None;
        for prec in [Precision::F32, Precision::F64] {
            let mut cpu = CpuEngine::new(
                &basis,
                &feats,
                CpuOptions {
                    precision: prec,
                    materialize_limit_bytes: 0,
                },
            )
            .expect("cpu engine");
            let mut cout = vec![0.0; n_c];
            cpu.sweep(&v, &mut cout).expect("cpu sweep");
            let cpu_reps = if pairs > cpu_max_pairs {
                1
            } else {
                reps.min(5)
            };
            let cmed = median_time(cpu_reps, || cpu.sweep(&v, &mut cout).expect("cpu sweep"));
            // A path costs a little over one sweep per step; cut it to the budget.
            let cpu_steps = ((cpu_path_budget / (1.2 * cmed)) as usize).clamp(2, steps);
            let t = Instant::now();
            let cpath = lars_path(
                &mut cpu,
                &y,
                None,
                &PathOptions {
                    max_steps: cpu_steps,
                    ..path_opts
                },
            )
            .expect("cpu path");
            let ran = cpath.breakpoints.len() - 1;
            let mut cpath_s = t.elapsed().as_secs_f64();
            let extrap = ran < gpu_steps;
            if extrap {
                cpath_s *= gpu_steps as f64 / ran.max(1) as f64;
            }
            if prec == Precision::F64 {
                // Where the active sets first differ from the f64 path's, for the GPU and for the
                // CPU engine's own f32 products: deep in the noise, near-ties among candidates
                // break differently in f32 (printed, not failed: docs/gpu.md).
                let k = ran.min(gpu_steps);
                let gpu_at = first_difference(&gpu_path, &cpath, k);
                let f32_at = f32_path
                    .as_ref()
                    .and_then(|p| first_difference(p, &cpath, k));
                let at = |d: Option<usize>| d.map_or("same".to_string(), |s| format!("step {s}"));
                order_ok = format!("{} / {} (of {k})", at(gpu_at), at(f32_at));
            }
            if prec == Precision::F32 {
                f32_path = Some(cpath);
            }
            cpu_cells.push(format!(
                "{:.1} ms / {}x | {:.2} s{} / {}x",
                cmed * 1e3,
                ratio(cmed / med),
                cpath_s,
                if extrap { " extrap." } else { "" },
                ratio(cpath_s / gpu_path_s)
            ));
        }

        rows_out.push(format!(
            "| {n_s} x {n_c} (n_z={n_z}, d={d}) | {:.3} ms | {:.1} % | {:.2} s ({gpu_steps} steps) | {} | {} | {order_ok} | {worst:.1e} {} | {:.2} s / {:.0} ms |",
            med * 1e3,
            100.0 * pairs / peak / med,
            gpu_path_s,
            cpu_cells[0],
            cpu_cells[1],
            if ok { "ok" } else { "FAIL" },
            setup,
            first * 1e3,
        ));
    }
    if !shape_rows.is_empty() {
        println!("\nKernel shapes ({n_s} samples; sweep: median of {reps}; max rel err vs f64 on {n_check} candidates)\n");
        println!("| problem | shape | sweep | pairs/s | max rel err |");
        println!("|---|---|---|---|---|");
        for r in &shape_rows {
            println!("{r}");
        }
    }
    if shapes_only {
        if failed {
            eprintln!("gpu_report: correctness check FAILED (max rel err >= 1e-5)");
            std::process::exit(1);
        }
        return;
    }
    let threads = rayon::current_num_threads();
    println!("\nGPU engine report ({n_s} samples; sweeps: median of {reps}; paths: LassoLars, {steps} steps/terms at most, active-set work included; CPU engine on {threads} threads, same run; ratio = CPU time / GPU time)\n");
    println!("| problem | GPU sweep | of arithmetic limit ({peak:.2e} pairs/s) | GPU path | CPU f32 sweep / ratio | CPU f32 path / ratio | CPU f64 sweep / ratio | CPU f64 path / ratio | active set leaves CPU f64's: GPU / CPU f32 | max rel err vs f64 | GPU setup / first sweep |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows_out {
        println!("{r}");
    }
    if failed {
        eprintln!("gpu_report: correctness check FAILED (max rel err >= 1e-5, )");
        std::process::exit(1);
    }
}

/// The first step (1..=k) at which two paths' active sets differ.
fn first_difference(
    a: &ctsid::regression::Path,
    b: &ctsid::regression::Path,
    k: usize,
) -> Option<usize> {
    (1..=k).find(|&s| a.breakpoints[s].active != b.breakpoints[s].active)
}

/// `WGxR:FD` then `s` (scalar code) or `a` (arrays), then optionally `/CHUNK`, e.g. `64x8:3s`,
/// `128x4:2s/64`.
fn parse_shape(x: &str) -> Option<KernelShape> {
    let (x, chunk) = match x.split_once('/') {
        Some((x, c)) => (x, c.parse().ok()?),
        None => (x, KernelShape::default().max_chunk),
    };
    let (wg, rest) = x.split_once('x')?;
    let (r, rest) = rest.split_once(':')?;
    let scalar_code = match rest.chars().last()? {
        's' => true,
        'a' => false,
        _ => return None,
    };
    Some(KernelShape {
        workgroup: wg.parse().ok()?,
        per_invocation: r.parse().ok()?,
        max_factor_degree: rest[..rest.len() - 1].parse().ok()?,
        scalar_code,
        max_chunk: chunk,
    })
}

/// Largest |GPU - exact| / sum_i |x_ij v_i| over a spread subset of candidates (first, last,
/// evenly spaced), every element checked.
fn worst_error(
    out: &[f64],
    rows: &[f64],
    n_z: usize,
    basis: &Basis,
    v: &[f64],
    n_check: usize,
) -> f64 {
    let n_c = basis.len();
    let step = (n_c / n_check.max(1)).max(1);
    let mut idx: Vec<usize> = (0..n_c).step_by(step).collect();
    if *idx.last().unwrap() != n_c - 1 {
        idx.push(n_c - 1);
    }
    let sub: Vec<Code> = idx.iter().map(|&j| basis.code(j)).collect();
    let (mut want, mut mag) = (vec![0.0; sub.len()], vec![0.0; sub.len()]);
    naive_f64_sweep(rows, n_z, &sub, v, &mut want, Some(&mut mag));
    let mut worst = 0.0f64;
    for (k, &j) in idx.iter().enumerate() {
        let rel = if out[j].is_finite() {
            (out[j] - want[k]).abs() / mag[k].max(f64::MIN_POSITIVE)
        } else {
            f64::INFINITY
        };
        worst = worst.max(rel);
    }
    worst
}

fn median_time(reps: usize, mut f: impl FnMut()) -> f64 {
    let mut times: Vec<f64> = (0..reps.max(1))
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    times[times.len() / 2]
}

/// Two or three significant digits (ratios span 1e-3 on lavapipe to 1e3 on a real GPU).
fn ratio(x: f64) -> String {
    if x >= 10.0 {
        format!("{x:.0}")
    } else if x >= 1.0 {
        format!("{x:.1}")
    } else {
        format!("{x:.3}")
    }
}
