//! End to end: the GPU device is lost in the middle of a LARS path inside `Regression::fit`;
//! the fit falls back to the CPU engine, says so in one line (stderr and the model's notes) and
//! returns the CPU engine's model. The loss is real (`wgpu::Device::destroy`), injected with
//! `CTSID_GPU_LOSE_DEVICE_AFTER` (read when the engine is built), so this test has a binary of
//! its own: the variable must not leak into other tests.
//!
//! Without an adapter it skips with a notice, unless CTSID_REQUIRE_GPU=1.
#![cfg(feature = "gpu")]

use ctsid::engine::Features;
use ctsid::regression::{EngineChoice, Regression};

#[test]
fn a_device_lost_mid_path_falls_back_to_the_cpu_engine_with_one_line() {
    if ctsid::engine::gpu::probe_adapters().is_empty() {
        assert!(
            std::env::var("CTSID_REQUIRE_GPU").as_deref() != Ok("1"),
            "CTSID_REQUIRE_GPU=1 but there is no GPU adapter"
        );
        println!("skipping: no GPU adapter");
        return;
    }
    let n = 1500;
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut s = 0x5EEDu64;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for _ in 0..n {
        a.push(next());
        b.push(next());
    }
    let y: Vec<f64> = (0..n)
        .map(|i| 2.0 * a[i] * b[i] - 0.5 * a[i].powi(3) + 0.3 + 1e-3 * next())
        .collect();
    let f = Features::new(vec!["a".into(), "b".into()], vec![a, b]).unwrap();
    let build = |e| {
        Regression::builder()
            .degree(4)
            .engine(e)
            .precision(ctsid::engine::Precision::F64)
            .build()
            .unwrap()
    };
    // Lost after the column statistics and three sweeps: in the middle of the path.
    std::env::set_var("CTSID_GPU_LOSE_DEVICE_AFTER", "3");
    let m = build(EngineChoice::Gpu).fit(&f, &y, "y", None).unwrap();
    std::env::remove_var("CTSID_GPU_LOSE_DEVICE_AFTER");
    let notes = &m.diagnostics.notes;
    let fell: Vec<&String> = notes
        .iter()
        .filter(|l| l.contains("falling back"))
        .collect();
    assert_eq!(fell.len(), 1, "{notes:?}");
    assert!(
        fell[0].contains("device lost") && !fell[0].contains('\n'),
        "{}",
        fell[0]
    );
    assert!(
        m.diagnostics.engine.starts_with("cpu"),
        "{}",
        m.diagnostics.engine
    );
    let cpu = build(EngineChoice::Cpu).fit(&f, &y, "y", None).unwrap();
    assert_eq!(m.equation(), cpu.equation());
    assert!(m.equation().contains("a*b"), "{}", m.equation());
    println!("{}\n{}", fell[0], m.equation());
}
