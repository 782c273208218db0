//! Runs sweeps only, for `perf stat` cycle counts (robust to other load on the machine):
//! `perf stat -e cycles:u target/release/deps/sweep_cycles-* NZ D REPS [32|64] [1: column statistics instead]` (built by `cargo bench --bench sweep_cycles --no-run`).
use ctsid::basis::{Basis, BasisLimits};
use ctsid::engine::{CpuEngine, CpuOptions, Features, Precision, SweepEngine};

fn main() {
    let a: Vec<usize> = std::env::args()
        .filter(|a| a != "--bench")
        .skip(1)
        .map(|s| s.parse().unwrap())
        .collect();
    let (nz, d, reps) = (a[0], a[1], a[2]);
    let prec = if a.get(3) == Some(&64) {
        Precision::F64
    } else {
        Precision::F32
    };
    let n = 25_000;
    let mut s = 1u64;
    let mut u = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let names: Vec<String> = (0..nz).map(|k| format!("z{k}")).collect();
    let cols = (0..nz).map(|_| (0..n).map(|_| u()).collect()).collect();
    let f = Features::new(names.clone(), cols).unwrap();
    let b = Basis::new(&names, d, BasisLimits::default()).unwrap();
    let mut e = CpuEngine::new(
        &b,
        &f,
        CpuOptions {
            precision: prec,
            materialize_limit_bytes: 0,
        },
    )
    .unwrap();
    let v: Vec<f64> = (0..n).map(|_| u()).collect();
    if a.get(4) == Some(&1) {
        // Column statistics under weights (the robust passes' case).
        let w: Vec<f64> = v.iter().map(|x| 0.5 + 0.5 * x.abs()).collect();
        let t = std::time::Instant::now();
        let mut c = 0.0;
        for _ in 0..reps {
            c += e.column_stats(Some(&w)).unwrap().norm.iter().sum::<f64>();
        }
        let dt = t.elapsed().as_secs_f64() / reps as f64;
        eprintln!("column stats: wall {dt:.4} s each; checksum {c:.9e}");
        return;
    }
    let mut out = vec![0.0; b.len()];
    let t = std::time::Instant::now();
    for _ in 0..reps {
        e.sweep(&v, &mut out).unwrap();
    }
    let dt = t.elapsed().as_secs_f64() / reps as f64;
    eprintln!(
        "pairs per sweep {:.4e}; wall {:.4} s per sweep; checksum {:.6e}; bits {:016x}",
        (n * b.len()) as f64,
        dt,
        out.iter().sum::<f64>(),
        // The exact bits of every sum, to tell a kernel that changes no rounding.
        out.iter()
            .fold(0u64, |h, x| (h ^ x.to_bits()).wrapping_mul(0x100000001b3))
    );
}
