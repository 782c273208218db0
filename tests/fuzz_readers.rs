//! Property tests over the readers a user's text reaches: the CSV reader, the run-list parser,
//! the expression parser and the model-file reader. Random and mutated inputs must give `Ok`
//! or an error whose message is one line of bounded length; never a panic or a hang.
//! Seeded (deterministic); a few hundred cases each, well under a minute in all.

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

use ctsid::identify::split::parse_list_at_most;
use ctsid::model::{Expr, Model};
use ctsid::records::{CsvSpec, RecordSet};

fn config(seed: u64) -> Config {
    Config {
        cases: 1000,
        rng_seed: RngSeed::Fixed(seed),
        failure_persistence: None,
        ..Config::default()
    }
}

/// An error a user will read: one line, not the whole input echoed back.
fn one_line<T>(r: ctsid::Result<T>, input_len: usize) -> Result<(), TestCaseError> {
    if let Err(e) = r {
        let m = e.to_string();
        prop_assert!(!m.contains('\n'), "not one line: {m}");
        prop_assert!(m.len() < 3000 + input_len.min(3000), "{} bytes", m.len());
    }
    Ok(())
}

const CSV: &str = "run,t,u,y\n0,0.00,1.0,0.5\n0,0.01,0.9,0.6\n0,0.02,0.8,0.7\n1,0.00,0.1,0.2\n1,0.01,0.2,0.3\n1,0.02,0.3,0.35\n";

const MODEL: &str = r#"{"format":"ctsid-model/2","tau":0.01,"inputs":["u"],"sign_smoothing":{"y_d1":0.001},"outputs":[{"name":"y","order":2,"terms":[{"exponents":{"y":1},"coefficient":-1.5},{"exponents":{"u":1,"y_d1":2},"coefficient":0.25},{"expression":"sign(y_d1)*sqrt(abs(y))","coefficient":-0.1,"std_error":0.01,"interval":[-0.12,-0.08],"origin":{"effect":"coulomb_friction"}}]}]}"#;

/// `base` with a few bytes replaced, inserted or deleted at random places.
fn mutated(base: &'static str) -> impl Strategy<Value = Vec<u8>> {
    let edits = prop::collection::vec((any::<u16>(), any::<u8>(), 0u8..3), 1..6);
    edits.prop_map(move |edits| {
        let mut b = base.as_bytes().to_vec();
        for (pos, byte, kind) in edits {
            let at = pos as usize % (b.len() + 1);
            match kind {
                0 if at < b.len() => b[at] = byte,
                1 => b.insert(at, byte),
                _ if at < b.len() => {
                    b.remove(at);
                }
                _ => {}
            }
        }
        b
    })
}

fn read_csv(bytes: &[u8]) -> ctsid::Result<RecordSet> {
    let spec = CsvSpec {
        columns: vec!["u".into(), "y".into()],
        run_column: Some("run".into()),
        time_column: Some("t".into()),
        tau: None,
        rows_independent: false,
    };
    RecordSet::from_reader(bytes, "fuzz.csv", &spec)
}

proptest! {
    #![proptest_config(config(0xC5F1))]
    #[test]
    fn csv_reader_takes_mutated_records(bytes in mutated(CSV)) {
        one_line(read_csv(&bytes), bytes.len())?;
    }

    #[test]
    fn csv_reader_takes_arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        one_line(read_csv(&bytes), bytes.len())?;
    }
}

proptest! {
    #![proptest_config(config(0x2A15))]
    #[test]
    fn run_lists_of_any_text(text in "[0-9a-z,:\\-. ]{0,40}|\\PC{0,40}") {
        one_line(parse_list_at_most(&text, "run", 1000), text.len())?;
    }

    #[test]
    fn huge_run_ranges_are_counted_not_expanded(a in any::<u64>(), b in any::<u64>()) {
        let text = format!("{a}-{b},{b}-{a},{}-{}", a % 1000, b % 100_000);
        let r = parse_list_at_most(&text, "run", 10_000);
        if let Ok(v) = &r {
            prop_assert!(v.len() <= 10_000);
        }
        one_line(r, text.len())?;
    }
}

proptest! {
    #![proptest_config(config(0xE4B1))]
    #[test]
    fn expressions_of_any_text(text in "[a-z_0-9+\\-*/^(). ,]{0,40}|\\PC{0,30}") {
        let vars = vec!["y".to_string(), "y_d1".to_string(), "u".to_string()];
        one_line(Expr::parse(&text, &vars), text.len())?;
    }

    #[test]
    fn expressions_built_from_parts(parts in prop::collection::vec(
        prop::sample::select(vec!["sign(", "abs(", "sqrt(", "tanh(", "sat(", "relu(", "exp(", ")", "y", "y_d1", "u", "+", "-", "*", "/", "^", "2", "0.5", "1e308", "(", " "]), 0..20)) {
        let text: String = parts.concat();
        let vars = vec!["y".to_string(), "y_d1".to_string(), "u".to_string()];
        one_line(Expr::parse(&text, &vars), text.len())?;
    }
}

proptest! {
    #![proptest_config(config(0x30DE))]
    #[test]
    fn model_reader_takes_mutated_files(bytes in mutated(MODEL)) {
        let text = String::from_utf8_lossy(&bytes).to_string();
        let r = Model::from_json_str(&text, "fuzz.json");
        // What reads must also compile (and so simulate) or say why.
        if let Ok(m) = &r {
            one_line(m.compile(), text.len())?;
        }
        one_line(r, text.len())?;
    }
}
