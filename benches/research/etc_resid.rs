//! Diagnostic: where the largest order-3 residuals of the noise-free throttle sit.
#![allow(clippy::needless_range_loop)]
use ctsid::demo::records;
use ctsid::identify::{identify, Orders, Settings, Split};
use ctsid::plants::{dataset, Plant, ThrottlePreset};
fn main() {
    let eta: f64 = std::env::args()
        .filter(|a| a != "--bench")
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(0.0);
    let plant = Plant::throttle(ThrottlePreset::Paper { patm: 0.0 });
    let runs = dataset(&plant, 30, 1000, 0.003, eta, 1).unwrap();
    let rs = records(&runs, &plant.input_names(), &plant.output_names(), 0.003).unwrap();
    let ids: Vec<String> = (0..30).map(|i| i.to_string()).collect();
    let split = Split::new((0..25).collect(), None, (25..30).collect(), &ids).unwrap();
    let mut s = Settings::new(vec!["y".into()], vec!["u".into()], 1);
    s.orders = Orders::Fixed(vec![3]);
    s.engine = ctsid::regression::EngineChoice::Cpu;
    let id = identify(&rs, &split, &s).unwrap();
    println!("{}", id.model.outputs[0].to_text());
    let c = id.model.compile().unwrap();
    let mut rows = Vec::new();
    let sig: Vec<f64> = (0..25)
        .flat_map(|r| id.derivatives[0][r].sigma[3].clone())
        .collect();
    let sref = ctsid::derivatives::score::percentile(&sig, 50.0);
    for r in 0..25 {
        let d = &id.derivatives[0][r];
        for i in 0..1000 {
            let z = [
                d.values[0][i],
                d.values[1][i],
                d.values[2][i],
                runs[r].u[0][i],
            ];
            let e = d.values[3][i] - c.eval_output(0, &z).unwrap();
            rows.push((
                e.abs(),
                r,
                i,
                d.values[3][i],
                runs[r].derivatives[0][3][i],
                d.sigma[3][i] / sref,
                runs[r].u[0][i],
            ));
        }
    }
    rows.sort_by(|a, b| b.0.total_cmp(&a.0));
    for x in rows.iter().filter(|x| x.5 <= 5.0).take(12) {
        println!(
            "|e| {:.3e} run {} i {} label {:.3e} true {:.3e} sigma/ref {:.2} u {:.3}",
            x.0, x.1, x.2, x.3, x.4, x.5, x.6
        );
    }
    println!("train profile {:?}", id.outputs[0].candidates[0].train.0);
}
