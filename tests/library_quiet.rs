//! The library prints nothing: progress goes to a callback, notes into the results, and the
//! Vulkan loader's complaint about XDG_RUNTIME_DIR (32 lines from one identification) is
//! avoided inside the library. The test reruns itself as a child process with that variable
//! unset and looks at everything the child wrote.

use std::process::Command;

use ctsid::engine::Features;
use ctsid::regression::EngineChoice;
use ctsid::regression::Regression;

const CHILD: &str = "CTSID_LIBRARY_QUIET_CHILD";

fn work() {
    let _ = ctsid::engine::select::probe();
    let n = 400;
    let a: Vec<f64> = (0..n)
        .map(|i| ((i * 37) % 101) as f64 / 50.0 - 1.0)
        .collect();
    let b: Vec<f64> = (0..n)
        .map(|i| ((i * 53) % 97) as f64 / 48.0 - 1.0)
        .collect();
    let y: Vec<f64> = a.iter().zip(&b).map(|(a, b)| 2.0 * a - a * b).collect();
    let f = Features::new(vec!["a".into(), "b".into()], vec![a, b]).unwrap();
    for engine in [EngineChoice::Auto, EngineChoice::Gpu, EngineChoice::Cpu] {
        let reg = Regression::builder()
            .degree(2)
            .engine(engine)
            .build()
            .unwrap();
        let _ = reg.fit(&f, &y, "y", None);
    }
}

#[test]
fn the_library_prints_nothing() {
    if std::env::var_os(CHILD).is_some() {
        work();
        return;
    }
    let me = std::env::current_exe().unwrap();
    let out = Command::new(me)
        .args([
            "--exact",
            "the_library_prints_nothing",
            "--nocapture",
            "--test-threads",
            "1",
        ])
        .env(CHILD, "1")
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    // The test harness's own lines are not the library's.
    let printed: Vec<&str> = text
        .lines()
        .filter(|l| {
            let l = l.trim();
            !(l.is_empty()
                || l.starts_with("running ")
                || l.starts_with("test ")
                || l.starts_with("test result:")
                || l.starts_with("successes:")
                || l.starts_with("the_library_prints_nothing"))
        })
        .collect();
    assert!(printed.is_empty(), "the library printed: {printed:?}");
}
