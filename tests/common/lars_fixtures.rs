//! The scikit-learn `lars_path` fixtures in tests/data/lars (copied from ../shared/fixtures/lars;
//! see the README there), shared by the CPU conformance tests and the GPU parity tests.

use ctsid::basis::{Basis, BasisLimits, Code};
use ctsid::engine::Features;
use ctsid::regression::Method;
use serde_json::Value;

pub struct Fixture {
    pub name: String,
    pub method: Method,
    /// Raw variables, row-major.
    pub z: Vec<Vec<f64>>,
    /// Exponents of the fixture's columns (the basis without the constant).
    pub exponents: Vec<Vec<u32>>,
    /// The standardised design, column by column.
    pub x_cols: Vec<Vec<f64>>,
    pub y: Vec<f64>,
    pub alphas: Vec<f64>,
    pub coefs: Vec<Vec<f64>>,
    pub active: Vec<usize>,
}

impl Fixture {
    /// Path steps of the reference (breakpoints after the first).
    pub fn steps(&self) -> usize {
        self.alphas.len() - 1
    }
}

/// Every fixture, in file-name order.
pub fn load() -> Vec<Fixture> {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/lars");
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    assert!(files.len() >= 7, "fixtures missing in {dir}");
    files
        .iter()
        .map(|p| {
            let v: Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
            let arr = |x: &Value| x.as_array().unwrap().clone();
            let vecf =
                |x: &Value| -> Vec<f64> { arr(x).iter().map(|e| e.as_f64().unwrap()).collect() };
            let mat = |k: &str| -> Vec<Vec<f64>> { arr(&v[k]).iter().map(vecf).collect() };
            let x = mat("X");
            let p_ = x[0].len();
            Fixture {
                name: v["name"].as_str().unwrap().to_string(),
                method: if v["method"] == "lar" {
                    Method::Lars
                } else {
                    Method::LassoLars
                },
                z: mat("Z"),
                exponents: arr(&v["exponents"])
                    .iter()
                    .map(|r| arr(r).iter().map(|e| e.as_u64().unwrap() as u32).collect())
                    .collect(),
                x_cols: (0..p_).map(|j| x.iter().map(|r| r[j]).collect()).collect(),
                y: vecf(&v["y"]),
                alphas: vecf(&v["alphas"]),
                coefs: mat("coefs"),
                active: arr(&v["active"])
                    .iter()
                    .map(|e| e.as_u64().unwrap() as usize)
                    .collect(),
            }
        })
        .collect()
}

/// The fixture's candidates through the basis: its columns are the basis without the constant,
/// in the same order (checked), and X is these columns standardised.
pub fn problem(f: &Fixture) -> (Basis, Features) {
    let nz = f.z[0].len();
    let degree = f
        .exponents
        .iter()
        .map(|e| e.iter().sum::<u32>())
        .max()
        .unwrap() as usize;
    let names: Vec<String> = (0..nz).map(|k| format!("z{k}")).collect();
    let basis = Basis::new(&names, degree, BasisLimits::default()).unwrap();
    assert_eq!(basis.len(), f.exponents.len() + 1, "{}", f.name);
    for (j, e) in f.exponents.iter().enumerate() {
        assert_eq!(
            basis.code(j + 1),
            Code::from_exponents(e).unwrap(),
            "{}: column {j}",
            f.name
        );
    }
    let feats = Features::new(
        names,
        (0..nz)
            .map(|k| f.z.iter().map(|r| r[k]).collect())
            .collect(),
    )
    .unwrap();
    (basis, feats)
}
