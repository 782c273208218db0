//! Report output: Markdown and CSV tables and SVG figures written by `--out` / `--report`
//! folders: [`compare`] (measured against simulated, with the residual analysis of [`resid`])
//! for every command that simulates, drawn by [`svg`].

pub mod compare;
pub mod resid;
pub mod svg;

use crate::error::{Error, Result};
use std::path::Path;

/// Writes a text file, creating the folder, with an error naming the path. Characters of `name`
/// other than ASCII letters, digits and `._-` become `_` (names carry run ids from the data). Errs
/// when the folder cannot be created or the file cannot be written.
pub fn write_file(dir: &Path, name: &str, text: &str) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir.display().to_string(), e))?;
    // Names carry run ids and channel names from the data: keep them inside `dir`.
    let p = dir.join(safe_name(name));
    crate::util::write_atomic(&p, text.as_bytes())
}

/// `name` as [`write_file`] names its file: characters other than ASCII letters, digits and
/// `._-` become `_`.
pub fn safe_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "._-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// A table rendered as Markdown and as CSV from the same rows.
pub struct Table {
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

impl Table {
    pub fn new(header: &[&str]) -> Table {
        Table {
            header: header.iter().map(|s| s.to_string()).collect(),
            rows: Vec::new(),
        }
    }

    pub fn row(&mut self, cells: Vec<String>) {
        self.rows.push(cells);
    }

    pub fn markdown(&self) -> String {
        let mut s = format!(
            "| {} |\n|{}|\n",
            self.header.join(" | "),
            vec!["---"; self.header.len()].join("|")
        );
        for r in &self.rows {
            s += &format!("| {} |\n", r.join(" | "));
        }
        s
    }

    pub fn csv(&self) -> String {
        let q = |c: &String| {
            if c.contains(',') || c.contains('"') {
                format!("\"{}\"", c.replace('"', "\"\""))
            } else {
                c.clone()
            }
        };
        let mut s = self.header.iter().map(q).collect::<Vec<_>>().join(",") + "\n";
        for r in &self.rows {
            s += &(r.iter().map(q).collect::<Vec<_>>().join(",") + "\n");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn file_names_from_the_data_stay_in_the_folder() {
        let dir = std::env::temp_dir().join(format!("ctsid-report-{}", std::process::id()));
        super::write_file(&dir, "test_run_../exp/5.svg", "x").unwrap();
        assert!(dir.join("test_run_.._exp_5.svg").is_file());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
