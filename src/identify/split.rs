//! Run splits: which runs train, validate and test a model. Lists are written like `0-24,30`
//! and name run ids as they appear in the record set (numeric ids may be given as ranges).

use crate::error::{Error, Result};

/// Parses `0-24,30,a7` into a list of run ids (ranges expand over integers). Refuses a range that
/// runs backwards, more than 10,000,000 names, and a list that names nothing.
pub fn parse_runs(text: &str) -> Result<Vec<String>> {
    parse_list(text, "runs")
}

/// As [`parse_runs`], with `what` naming the setting in errors (`train`, `orders`, ...). Refuses
/// what [`parse_runs`] refuses.
pub fn parse_list(text: &str, what: &str) -> Result<Vec<String>> {
    parse_list_at_most(text, what, 10_000_000)
}

/// One item of a list: `RUN#` prefix or none, the rest, and its range when it is one.
struct Item<'t> {
    whole: &'t str,
    prefix: String,
    part: &'t str,
    range: Option<(i64, i64)>,
}

impl Item<'_> {
    /// Names the item stands for (a range counts each of its numbers).
    fn count(&self) -> u64 {
        self.range.map_or(1, |(a, b)| (b - a) as u64 + 1)
    }
}

/// The items of a list, unexpanded; refuses a range that runs backwards. An item that `is_id`
/// names a run by (`2024-05`, `1-2`) is that run, not a range.
fn items<'t>(text: &'t str, what: &str, is_id: &dyn Fn(&str) -> bool) -> Result<Vec<Item<'t>>> {
    let mut out = Vec::new();
    for whole in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        if is_id(whole) {
            out.push(Item {
                whole,
                prefix: String::new(),
                part: whole,
                range: None,
            });
            continue;
        }
        // Pieces of a cut run (`RUN#0-4`, see `RecordSet::segmented`) take ranges too.
        let (prefix, part) = match whole.rsplit_once('#') {
            Some((run, rest)) => (format!("{run}#"), rest),
            None => (String::new(), whole),
        };
        let range = part.split_once('-').and_then(|(a, b)| {
            Some((a.trim().parse::<i64>().ok()?, b.trim().parse::<i64>().ok()?))
        });
        if let Some((a, b)) = range {
            if b < a {
                return Err(Error::param(
                    what,
                    format!("range '{whole}' runs backwards; write {prefix}{b}-{a}"),
                ));
            }
        }
        out.push(Item {
            whole,
            prefix,
            part,
            range,
        });
    }
    Ok(out)
}

/// How many names a list stands for, counted without expanding its ranges (`1-9999999` is
/// 9,999,999); refuses what [`parse_list`] refuses of a list's form (a backwards range).
pub fn count_names(text: &str, what: &str) -> Result<u64> {
    Ok(items(text, what, &|_| false)?
        .iter()
        .fold(0u64, |n, it| n.saturating_add(it.count())))
}

/// [`parse_list`] of at most `most` names, counted before any range is expanded: a list of
/// run ids need not name more runs than the record has, and `0-10000000` eight times over
/// would otherwise take gigabytes before the first unknown id is found. Refuses a range that runs
/// backwards, more than `most` names, and a list that names nothing.
pub fn parse_list_at_most(text: &str, what: &str, most: usize) -> Result<Vec<String>> {
    parse_items(text, what, most, &|_| false)
}

/// [`parse_list_at_most`] of a list of the runs `ids` (at most as many names as runs): an item
/// that is a run id exactly is that run, not a range (`2024-00` was refused as a backwards
/// range, and `1-2` meant runs 1 and 2 beside a run named `1-2`).
pub fn parse_runs_among(text: &str, what: &str, ids: &[String]) -> Result<Vec<String>> {
    let known: std::collections::HashSet<&str> = ids.iter().map(String::as_str).collect();
    parse_items(text, what, ids.len().max(1), &|w| known.contains(w))
}

/// The indices in `ids` of the runs a list names: [`parse_runs_among`], then [`resolve`].
pub fn resolve_list(text: &str, ids: &[String], what: &str) -> Result<Vec<usize>> {
    resolve(&parse_runs_among(text, what, ids)?, ids, what)
}

fn parse_items(
    text: &str,
    what: &str,
    most: usize,
    is_id: &dyn Fn(&str) -> bool,
) -> Result<Vec<String>> {
    let items = items(text, what, is_id)?;
    let mut count: u64 = 0;
    for it in &items {
        count = count.saturating_add(it.count());
        if count > most as u64 {
            let shown: String = it.whole.chars().take(40).collect();
            return Err(Error::param(
                what,
                format!(
                    "the list names more than {most} (at '{shown}'); there are only {most} to name"
                ),
            ));
        }
    }
    let mut out = Vec::with_capacity(count as usize);
    for it in items {
        match it.range {
            Some((a, b)) => out.extend((a..=b).map(|i| format!("{}{i}", it.prefix))),
            None => out.push(format!("{}{}", it.prefix, it.part)),
        }
    }
    if out.is_empty() {
        return Err(Error::param(what, format!("'{text}' names nothing")));
    }
    Ok(out)
}

/// Indices of the named runs in `ids`, with an error naming the first unknown one. A name
/// that is not an id itself but the run a piece was cut from (`RUN` for `RUN#0`, `RUN#1`, ...:
/// [`crate::records::RecordSet::segmented`]) names all its pieces. Refuses a name that is neither a
/// run id (exactly or as a number) nor a run cut into pieces.
pub fn resolve(names: &[String], ids: &[String], what: &str) -> Result<Vec<usize>> {
    // Lists separate ids by commas: a run 'a,b' cannot be named, and `--test 'a,b'` tested
    // runs 'a' and 'b' and trained on it. Refused where a list is given (a file whose ids hold
    // commas still simulates, derives and identifies without lists).
    if let Some(id) = ids.iter().find(|id| id.contains(',')) {
        return Err(Error::param(
            what,
            format!(
                "run id '{}' holds a comma, which separates the ids of a run list, so no list can name it; rename the run",
                crate::util::clip(id, 40)
            ),
        ));
    }
    // Exact ids, numeric ids and cut runs through tables: a list can name a run per row of a
    // large file (a scan per name took 30 s at 40,000 runs written `0.0`, `1.0`, ...).
    let mut exact = std::collections::HashMap::with_capacity(ids.len());
    let mut numeric = std::collections::HashMap::new();
    let mut pieces: std::collections::HashMap<&str, Vec<usize>> = Default::default();
    for (i, id) in ids.iter().enumerate() {
        exact.entry(id.as_str()).or_insert(i);
        if let Some(key) = numeric_key(id) {
            numeric.entry(key).or_insert(i);
        }
        if let Some((run, _)) = id.rsplit_once('#') {
            pieces.entry(run).or_default().push(i);
        }
    }
    let mut out = Vec::new();
    for n in names {
        // An exact id first; only then a numeric match ("1" for a run written "01").
        let one = exact
            .get(n.as_str())
            .copied()
            .or_else(|| numeric.get(&numeric_key(n)?).copied());
        if let Some(i) = one {
            out.push(i);
            continue;
        }
        match pieces.get(n.as_str()) {
            Some(p) => out.extend(p),
            None => {
                let shown: Vec<&str> = ids.iter().take(8).map(String::as_str).collect();
                return Err(Error::param(
                    what,
                    format!(
                        "run '{n}' does not exist (runs are: {}{})",
                        shown.join(", "),
                        if ids.len() > 8 { ", ..." } else { "" }
                    ),
                ));
            }
        }
    }
    Ok(out)
}

/// A run id's value as a number, as a table key (the bits of the f64, -0 as 0); `None` for an
/// id that is not a number or is NaN (which equals nothing).
fn numeric_key(id: &str) -> Option<u64> {
    let v = id.parse::<f64>().ok().filter(|v| !v.is_nan())?;
    Some(if v == 0.0 {
        0.0f64.to_bits()
    } else {
        v.to_bits()
    })
}

/// A checked split into train, validation (optional: k-fold over train) and test runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Split {
    pub train: Vec<usize>,
    pub validation: Option<Vec<usize>>,
    pub test: Vec<usize>,
}

impl Split {
    /// The split named by run lists as the CLI takes them (`"0-3"`, `"4,5"`, ids of the record
    /// set, ranges over numeric ids); refuses unknown runs, empty lists and overlaps. Also refuses
    /// a backward range, a list naming more runs than the record set has, and a run listed twice.
    ///
    /// ```
    /// use ctsid::records::{RecordSet, Run};
    /// use ctsid::Split;
    /// let run = |id: usize| {
    ///     Run::new(id.to_string(), vec![(0..50).map(|k| ((k * (id + 1)) as f64).sin()).collect()])
    /// };
    /// let records = RecordSet::new(0.1, vec!["y".into()], (0..6).map(run).collect())?;
    /// let split = Split::from_lists(&records, "0-3", Some("4"), "5")?;
    /// assert_eq!((split.train, split.validation, split.test), (vec![0, 1, 2, 3], Some(vec![4]), vec![5]));
    /// assert!(Split::from_lists(&records, "0-3", None, "3").is_err(), "run 3 in two lists");
    /// assert!(Split::from_lists(&records, "0-3", None, "9").is_err(), "no run 9");
    /// # Ok::<(), ctsid::Error>(())
    /// ```
    pub fn from_lists(
        records: &crate::records::RecordSet,
        train: &str,
        validation: Option<&str>,
        test: &str,
    ) -> Result<Split> {
        let ids: Vec<String> = records.runs.iter().map(|r| r.id.clone()).collect();
        let list = |text: &str, what: &str| resolve_list(text, &ids, what);
        let validation = validation.map(|v| list(v, "validation")).transpose()?;
        Split::new(list(train, "train")?, validation, list(test, "test")?, &ids)
    }

    /// Every run the split names: training, validation, test.
    pub fn runs(&self) -> impl Iterator<Item = usize> + '_ {
        self.train
            .iter()
            .chain(self.validation.iter().flatten())
            .chain(&self.test)
            .copied()
    }

    /// Refuses a named run (training, validation or test) shorter than the fit of a free run's
    /// initial state at `order` needs ([`crate::simulate::initial_window`]): every run is
    /// simulated from such a state for the scores and gates, and a shorter one scored NaN or
    /// `inf` (a refinement judged `inf -> inf`, discover's gates comparing inf with inf). `what`
    /// names the need in the error.
    pub fn require_free_runs(
        &self,
        rs: &crate::records::RecordSet,
        order: usize,
        what: &str,
    ) -> Result<()> {
        let min = crate::simulate::initial_window(order);
        match self.runs().find(|&r| rs.runs[r].len() < min) {
            Some(r) => Err(Error::RunTooShort {
                run: rs.runs[r].id.clone(),
                len: rs.runs[r].len(),
                min,
                what: what.to_string(),
            }),
            None => Ok(()),
        }
    }

    /// Validates that the lists are non-empty where required and do not overlap. Refuses an empty
    /// `train`, an empty (but given) `validation`, an index out of range of `ids`, a run in two
    /// lists and a run listed twice in one.
    pub fn new(
        train: Vec<usize>,
        validation: Option<Vec<usize>>,
        test: Vec<usize>,
        ids: &[String],
    ) -> Result<Split> {
        if train.is_empty() {
            return Err(Error::param("train", "no training runs"));
        }
        if validation.as_ref().is_some_and(|v| v.is_empty()) {
            return Err(Error::param(
                "validation",
                "an empty list; give runs, or none for folds over the training runs",
            ));
        }
        let split = Split {
            train,
            validation,
            test,
        };
        split.check(ids.len())?;
        let groups = split.lists();
        for (a, (na, la)) in groups.iter().enumerate() {
            for (nb, lb) in groups.iter().skip(a + 1) {
                let lb: std::collections::HashSet<&usize> = lb.iter().collect();
                if let Some(r) = la.iter().find(|r| lb.contains(r)) {
                    return Err(Error::param(
                        "split",
                        format!(
                            "run '{}' is in both {na} and {nb}; splits must not overlap",
                            ids[*r]
                        ),
                    ));
                }
            }
            if let Some((_, j)) = crate::util::first_repeat(la) {
                return Err(Error::param(
                    *na,
                    format!("run '{}' is listed twice", ids[la[j]]),
                ));
            }
        }
        Ok(split)
    }

    /// The three lists by name (no validation runs: an empty one).
    fn lists(&self) -> [(&'static str, &[usize]); 3] {
        [
            ("train", &self.train),
            ("validation", self.validation.as_deref().unwrap_or(&[])),
            ("test", &self.test),
        ]
    }

    /// Every index names one of `n_runs` runs (the fields are public: a split built by hand is
    /// checked again where it is used). Refuses an empty training list (a hand-built split
    /// without one was told "no samples to regress on") and an index of `n_runs` or more.
    pub fn check(&self, n_runs: usize) -> Result<()> {
        if self.train.is_empty() {
            return Err(Error::param("train", "no training runs"));
        }
        for (name, list) in self.lists() {
            if let Some(r) = list.iter().find(|&&r| r >= n_runs) {
                return Err(Error::param(
                    name,
                    format!("run index {r} is out of range: the record set has {n_runs} runs"),
                ));
            }
        }
        Ok(())
    }

    /// Deterministic k folds over the training runs (run i goes to fold i mod k). `k` is clamped to
    /// 2..=the number of training runs, and folds with an empty side are left out (one training run
    /// gives none).
    pub fn folds(&self, k: usize) -> Vec<(Vec<usize>, Vec<usize>)> {
        let k = k.clamp(2, self.train.len().max(2));
        (0..k)
            .map(|f| {
                type Indexed = Vec<(usize, usize)>;
                let (val, fit): (Indexed, Indexed) = self
                    .train
                    .iter()
                    .copied()
                    .enumerate()
                    .partition(|(i, _)| i % k == f);
                (
                    fit.into_iter().map(|x| x.1).collect::<Vec<usize>>(),
                    val.into_iter().map(|x| x.1).collect::<Vec<usize>>(),
                )
            })
            .filter(|(fit, val)| !fit.is_empty() && !val.is_empty())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids(n: usize) -> Vec<String> {
        (0..n).map(|i| i.to_string()).collect()
    }

    #[test]
    fn a_hand_built_split_without_training_runs_is_refused() {
        let s = Split {
            train: vec![],
            validation: None,
            test: vec![0],
        };
        assert_eq!(
            s.check(2).unwrap_err().to_string(),
            "invalid setting 'train': no training runs"
        );
    }

    #[test]
    fn parses_ranges_and_lists() {
        assert_eq!(parse_runs("0-3,7").unwrap(), ["0", "1", "2", "3", "7"]);
        // Run ids with a dash are runs, not ranges, where the record has them.
        let ids: Vec<String> = ["2024-00", "2024-01", "1-2", "1", "2"]
            .map(String::from)
            .into();
        assert_eq!(
            parse_runs_among("2024-01,1-2", "train", &ids).unwrap(),
            ["2024-01", "1-2"]
        );
        assert!(parse_runs("2024-00").is_err());
        assert_eq!(
            parse_runs_among("1-2", "train", &ids[3..]).unwrap(),
            ["1", "2"]
        );
        assert_eq!(parse_runs(" a, b ").unwrap(), ["a", "b"]);
        assert!(parse_runs("5-2").is_err());
        assert!(parse_runs(",").is_err());
    }

    #[test]
    fn an_exact_id_wins_over_a_numeric_match() {
        let id: Vec<String> = ["0", "01", "1"].iter().map(|s| s.to_string()).collect();
        assert_eq!(resolve(&["1".into()], &id, "test").unwrap(), [2]);
        assert_eq!(resolve(&["01".into()], &id, "test").unwrap(), [1]);
        // Without an exact id, "1.0" still finds run "01" first by value.
        assert_eq!(resolve(&["1.0".into()], &id, "test").unwrap(), [1]);
        let e = parse_list("4-1", "orders").unwrap_err().to_string();
        assert!(e.contains("'orders'"), "{e}");
        // Numeric matches through the table: -0 is 0, NaN is nothing, the first of equals wins.
        let id: Vec<String> = ["a", "-0.0", "2.50", "NaN", "2.5"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        assert_eq!(resolve(&["0".into()], &id, "test").unwrap(), [1]);
        assert_eq!(resolve(&["2.5e0".into()], &id, "test").unwrap(), [2]);
        assert!(resolve(&["nan".into()], &id, "test").is_err());
        assert_eq!(resolve(&["NaN".into()], &id, "test").unwrap(), [3]);
        // Many runs written as decimals, named by integers (was a scan per name).
        let id: Vec<String> = (0..50_000).map(|i| format!("{i}.0")).collect();
        let names: Vec<String> = (0..50_000).rev().map(|i| i.to_string()).collect();
        let got = resolve(&names, &id, "test").unwrap();
        assert_eq!(got[0], 49_999);
        assert_eq!(got[49_999], 0);
    }

    #[test]
    fn pieces_of_cut_runs_take_ranges_and_their_run_name() {
        assert_eq!(
            parse_runs("est#0-2,b#4").unwrap(),
            ["est#0", "est#1", "est#2", "b#4"]
        );
        let e = parse_runs("est#3-1").unwrap_err().to_string();
        assert!(e.contains("'est#3-1' runs backwards; write est#1-3"), "{e}");
        let id: Vec<String> = ["est#0", "est#1", "test#0", "test#1"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        // The run a piece was cut from names all its pieces; a piece names itself.
        assert_eq!(resolve(&["test".into()], &id, "test").unwrap(), [2, 3]);
        assert_eq!(resolve(&["est#1".into()], &id, "test").unwrap(), [1]);
        let e = resolve(&["es".into()], &id, "test")
            .unwrap_err()
            .to_string();
        assert!(e.contains("run 'es' does not exist"), "{e}");
    }

    #[test]
    fn split_errors_name_the_run() {
        let id = ids(10);
        let e = resolve(&parse_runs("3,12").unwrap(), &id, "test")
            .unwrap_err()
            .to_string();
        assert!(e.contains("'12' does not exist"), "{e}");
        let e = Split::new(vec![0, 1, 2], None, vec![2, 3], &id)
            .unwrap_err()
            .to_string();
        assert!(e.contains("run '2' is in both train and test"), "{e}");
        let s = Split::new(vec![0, 1, 2, 3, 4, 5], None, vec![7], &id).unwrap();
        let folds = s.folds(5);
        assert_eq!(folds.len(), 5);
        for (fit, val) in &folds {
            assert!(val.iter().all(|v| !fit.contains(v)));
            assert_eq!(fit.len() + val.len(), 6);
        }
    }
}
