//! `ctsid discover` end to end on a generated case: explicit run lists are honoured (the same
//! verdict as the library call with that split), overlapping or unknown lists are one-line errors.

mod common;

use common::cli::{ctsid, fails};
use ctsid::discover::{cases, discover, Options};

#[test]
fn discover_cli_uses_the_given_split() {
    // A case where an effect is added, so that a split the CLI ignored would show in the
    // coefficient (the negative control refuses whatever the split).
    let case = cases::generate("duffing", 0, 0.03).unwrap();
    let dir = std::env::temp_dir().join(format!("ctsid-discover-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let data = dir.join("d.csv");
    let rs = &case.records;
    let mut text = format!("run,t,{}\n", rs.channel_names.join(","));
    for r in &rs.runs {
        for i in 0..r.len() {
            let vals: Vec<String> = r.channels.iter().map(|c| format!("{:e}", c[i])).collect();
            text += &format!("{},{},{}\n", r.id, r.t0 + i as f64 * rs.tau, vals.join(","));
        }
    }
    std::fs::write(&data, text).unwrap();
    let nominal = dir.join("nominal.json");
    case.nominal.write(nominal.to_str().unwrap()).unwrap();
    let (train, val, test) = cases::split();
    let list = |v: &[usize]| {
        v.iter()
            .map(|r| rs.runs[*r].id.clone())
            .collect::<Vec<_>>()
            .join(",")
    };
    let (d, n) = (data.to_str().unwrap(), nominal.to_str().unwrap());
    let (tl, vl, sl) = (list(&train), list(&val), list(&test));
    // The options that every call shares (words() splits them).
    let base = "--run-column run --time-column t";
    let (ok, out, err) = ctsid(&[
        "discover",
        d,
        "--nominal",
        n,
        base,
        "--train",
        &tl,
        "--validation",
        &vl,
        "--test",
        &sl,
        "--report",
        dir.join("report").to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    // The report: evidence, a before/after plot and the residual analysis per test run, the
    // derivative residual along each coordinate.
    let rep = dir.join("report");
    for f in ["discovery.json", "summary.md"] {
        assert!(rep.join(f).is_file(), "{f} missing");
    }
    for r in &test {
        let svg =
            std::fs::read_to_string(rep.join(format!("test_run_{}.svg", rs.runs[*r].id))).unwrap();
        assert!(
            svg.starts_with("<svg")
                && svg.contains("nominal fit")
                && svg.contains("added model fit"),
            "{svg}"
        );
        let resid = rep.join(format!("resid_{}.svg", rs.runs[*r].id));
        assert!(resid.is_file(), "residual analysis of the test run missing");
    }
    assert!(rep.join("residual_along_y.svg").is_file());
    let mut lib = discover(rs, &case.nominal, &Options::new(train, val, test)).unwrap();
    assert_eq!(lib.verdict, "added", "{}", lib.text());
    assert!(
        out.lines()
            .any(|l| l == format!("verdict: {}", lib.verdict)),
        "library verdict '{}' not in CLI output:\n{out}",
        lib.verdict
    );
    // The same effects and coefficients as the library (the CSV round trip of the samples and
    // times moves them by rounding only).
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rep.join("discovery.json")).unwrap())
            .unwrap();
    assert_eq!(json["verdict"], lib.verdict.as_str());
    let effects = json["effects"].as_array().unwrap();
    assert_eq!(effects.len(), lib.effects.len(), "{json}");
    for (e, l) in effects.iter().zip(&lib.effects) {
        assert_eq!(e["family"], l.family.as_str());
        let c = e["coefficient"].as_f64().unwrap();
        assert!(
            (c - l.coefficient).abs() <= 1e-6 * l.coefficient.abs(),
            "{}: CLI {c} vs library {}",
            l.family,
            l.coefficient
        );
    }
    // Run ids with one safe file name (`a b`, `a_b`) get figures of their own: the second's
    // overwrote the first's.
    assert!(lib.test_runs.len() >= 2);
    lib.test_runs[0].id = "a b".into();
    lib.test_runs[1].id = "a_b".into();
    let names: Vec<String> = lib.plots().into_iter().map(|(n, _)| n).collect();
    let unique: std::collections::HashSet<&String> = names.iter().collect();
    assert_eq!(unique.len(), names.len(), "{names:?}");
    assert!(
        names.contains(&"test_run_a_b_2.svg".to_string()),
        "{names:?}"
    );

    fails(
        &[
            "discover",
            d,
            "--nominal",
            n,
            base,
            "--train",
            &tl,
            "--validation",
            &tl,
            "--test",
            &sl,
        ],
        &["in both train and validation"],
    );
    fails(
        &["discover", d, "--nominal", n, base, "--test 99"],
        &["run '99' does not exist"],
    );
    // An overlap between two given lists is named as such (it used to read as an empty
    // validation list), and so is an omitted list that no run is left for.
    let all: Vec<usize> = (0..rs.runs.len()).collect();
    fails(
        &[
            "discover",
            d,
            "--nominal",
            n,
            base,
            "--train",
            &list(&all[..5]),
            "--test",
            &list(&all[4..]),
        ],
        &[&format!(
            "run '{}' is in both train and test",
            rs.runs[4].id
        )],
    );
    fails(
        &["discover", d, "--nominal", n, base, "--train", &list(&all)],
        &[
            "'validation'",
            "no run is left",
            &format!("name all {} runs", all.len()),
        ],
    );
    fails(
        &[
            "discover",
            d,
            "--nominal",
            n,
            base,
            "--test",
            &list(&all[1..]),
        ],
        &[
            "'validation'",
            "the 1 run(s) the lists do not name went to train",
        ],
    );
    // One list given: the omitted ones share the other runs (they used to default to fixed
    // positions and clash with it).
    let (ok, out, err) = ctsid(&[
        "discover",
        d,
        "--nominal",
        n,
        base,
        "--train",
        &list(&[5, 6, 7, 8]),
    ]);
    assert!(ok, "{err}");
    assert!(
        out.contains("| 5 | train |") && out.contains("| 0 | validation |"),
        "{out}"
    );
}
