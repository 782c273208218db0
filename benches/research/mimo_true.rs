//! Diagnostic: sparse regression of the MIMO plant's y1''' on true derivatives (degree 3).
#![allow(clippy::needless_range_loop)]
use ctsid::engine::Features;
use ctsid::plants::{dataset, Plant};
use ctsid::regression::{EngineChoice, Regression};
fn main() {
    let plant = Plant::mimo();
    let runs = dataset(&plant, 25, 1000, 0.01, 0.0, 1).unwrap();
    let mut names = Vec::new();
    for o in ["y1", "y2", "y3"] {
        for k in 0..3 {
            names.push(if k == 0 {
                o.to_string()
            } else {
                format!("{o}_d{k}")
            });
        }
    }
    names.push("u1".into());
    names.push("u2".into());
    let mut cols = vec![Vec::new(); 11];
    let mut labels = vec![Vec::new(); 3];
    for r in &runs {
        for o in 0..3 {
            for k in 0..3 {
                cols[o * 3 + k].extend_from_slice(&r.derivatives[o][k]);
            }
            labels[o].extend_from_slice(&r.derivatives[o][3]);
        }
        cols[9].extend_from_slice(&r.u[0]);
        cols[10].extend_from_slice(&r.u[1]);
    }
    let f = Features::new(names, cols).unwrap();
    for o in 0..3 {
        let w: Vec<f64> = (0..labels[o].len())
            .map(|i| {
                if i % 1000 < 7 || i % 1000 > 992 {
                    0.0
                } else {
                    0.5 + 0.5 * (i as f64).sin().powi(2)
                }
            })
            .collect();
        let m = Regression::builder()
            .degree(3)
            .rss_floor(1e-7)
            .effective_samples(20000.0)
            .engine(EngineChoice::Cpu)
            .build()
            .unwrap()
            .fit(&f, &labels[o], "lab", Some(&w))
            .unwrap();
        println!(
            "{} terms: {}  (stop {:?}, {} steps)",
            m.terms.len(),
            m.equation(),
            m.diagnostics.stop,
            m.diagnostics.path_steps
        );
    }
}
