//! A benchmark's model file (one output) refitted on simulation error with other settings and run
//! sets, scored by the benchmark's protocol: the first metric's RMS, the validation runs'
//! free-run NRMSE and the last term's distance from zero in standard errors. Used to check what
//! a term added by hand would buy (docs/benchmarks.md, "The second look"): append it to the
//! model file with a small non-zero coefficient (a zero one stays zero in the refit's scaling).
//!
//! `cargo bench --bench bench_refit -- NAME MODEL.json [discover]` (`discover`: one discover
//! round against the model on the benchmark's split instead, its report printed).
use ctsid::benchmark::{fit_runs, load, test_scores};
use ctsid::identify::refine::{refine, RefineOptions};
use ctsid::Model;

fn main() {
    let args: Vec<String> = std::env::args().filter(|a| a != "--bench").collect();
    let (Some(name), Some(path)) = (args.get(1), args.get(2)) else {
        return println!("usage: bench_refit NAME MODEL.json [discover]");
    };
    let model = Model::read(path).unwrap();
    let b = match load(name, "../shared/data") {
        Ok(b) => b,
        Err(e) => return println!("skipped: {e}"),
    };
    let score = |m: &Model| test_scores(&b, m).unwrap().0;
    println!("start {:?}", score(&model));
    if args.get(3).map(|s| s.as_str()) == Some("discover") {
        let mut o = ctsid::discover::Options::new(
            b.split.train.clone(),
            b.split.validation.clone().unwrap_or_default(),
            Vec::new(),
        );
        o.refine_iterations = 15;
        let d = ctsid::discover::discover(&b.records, &model, &o).unwrap();
        println!("{}", d.text());
        return;
    }
    let sets: Vec<(&str, Vec<usize>)> = vec![
        ("train", b.split.train.clone()),
        (
            "train+val",
            b.split
                .train
                .iter()
                .chain(b.split.validation.as_ref().unwrap())
                .copied()
                .collect(),
        ),
    ];
    for (label, ids) in sets {
        for (tol, it) in [(1e-4, 15), (1e-7, 60)] {
            let runs = fit_runs(&b, &model, &ids).unwrap();
            let ro = RefineOptions {
                max_iterations: it,
                polish_iterations: 20,
                tolerance: tol,
                skip_below: 0.0,
                ..RefineOptions::default()
            };
            let t = std::time::Instant::now();
            let r = refine(&model, &runs, &ro).unwrap();
            let validation = b.split.validation.as_deref().unwrap_or_default();
            let val = fit_runs(&b, &r.model, validation).unwrap();
            let nv = ctsid::identify::refine::free_run_nrmse(&r.model, &val).unwrap();
            let last = r.model.outputs[0].terms.last().unwrap();
            println!(
                "{label} tol {tol:e} it {it}: {:?} val {:?} last t {:.1} ({:.1} s)",
                score(&r.model),
                nv,
                last.coefficient / last.std_error.unwrap_or(f64::NAN),
                t.elapsed().as_secs_f64()
            );
        }
    }
}
