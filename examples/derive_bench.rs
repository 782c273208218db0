//! Prints the derivative comparison table on shared/signals (experiment overrides by env vars).
fn main() {
    let dir = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "../shared/signals".into());
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    let opts = ctsid::derivatives::DerivativeOptions {
        states: env("CTSID_M").map(|v| v as usize),
        h: env("CTSID_H"),
        end_lambda: env("CTSID_LAMBDA").unwrap_or(0.5),
        adaptive: env("CTSID_ADAPT").map_or(true, |v| v != 0.0),
        window: env("CTSID_WIN").unwrap_or(2.0),
        end_blend: env("CTSID_ENDS").map_or(true, |v| v != 0.0),
    };
    let t = std::time::Instant::now();
    let rows = ctsid::derivatives::benchmark::run_with(std::path::Path::new(&dir), &opts).unwrap();
    println!("{}", ctsid::derivatives::benchmark::table(&rows));
    println!("elapsed {:?}", t.elapsed());
}
