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
    crate::util::Outputs::create_folder(dir)
        .map_err(|e| Error::file(dir.display().to_string(), e))?;
    // Names carry run ids and channel names from the data: keep them inside `dir`, and short
    // enough for the file system, with their extension.
    let file = match name.rsplit_once('.') {
        Some((stem, ext)) if !ext.is_empty() && ext.len() <= 8 => {
            format!("{}.{}", clean(stem, MAX_FILE_CHARS), clean(ext, 8))
        }
        _ => clean(name, MAX_FILE_CHARS),
    };
    let p = dir.join(file);
    crate::util::write_atomic(&p, text.as_bytes())
}

/// Characters of a name from the data that a file name stem keeps ([`safe_name`]): file systems
/// refuse names over 255 bytes, and a run id of 300 characters failed the report after its first
/// figures. Callers clip a name once, make it unique, then add their prefix and suffix; those
/// fit within `MAX_FILE_CHARS`, the last guard of [`write_file`].
pub const MAX_NAME_CHARS: usize = 120;

/// Characters [`write_file`] keeps of a file's stem (well under 255 bytes with any extension).
const MAX_FILE_CHARS: usize = 200;

/// `name` as a file name stem: characters other than ASCII letters, digits and `._-` become
/// `_`, and only the first [`MAX_NAME_CHARS`] are kept.
pub fn safe_name(name: &str) -> String {
    clean(name, MAX_NAME_CHARS)
}

/// `base` made unique among the stems in `used` (which it joins): a repeat takes `_2`, `_3`, ...
/// Runs `a b` and `a_b` (or `Lauf ä` and `Lauf ö`, or two ids that share their first
/// [`MAX_NAME_CHARS`]) have one [`safe_name`], and the second's figures overwrote the first's.
pub fn unique_stem(base: String, used: &mut std::collections::HashSet<String>) -> String {
    let mut stem = base.clone();
    let mut k = 1;
    while !used.insert(stem.clone()) {
        k += 1;
        stem = format!("{base}_{k}");
    }
    stem
}

/// `text` as one cell of a Markdown table: a `|` in it (a run id, an error text) would split it
/// into two columns and a line break would end the row, so they are escaped and made spaces.
pub fn md_cell(text: &str) -> String {
    text.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// The first `max` characters of `name`, those other than ASCII letters, digits and `._-` as `_`.
fn clean(name: &str, max: usize) -> String {
    name.chars()
        .take(max)
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
        let cells = |r: &[String]| -> String {
            r.iter().map(|c| md_cell(c)).collect::<Vec<_>>().join(" | ")
        };
        let mut s = format!(
            "| {} |\n|{}|\n",
            cells(&self.header),
            vec!["---"; self.header.len()].join("|")
        );
        for r in &self.rows {
            s += &format!("| {} |\n", cells(r));
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
        // A name of 300 characters: clipped, the extension kept (the OS refused the name). The
        // callers clip a run id first ([`safe_name`]), so their own prefixes and suffixes stay.
        let long = format!("sim_{}_y.svg", "L".repeat(300));
        super::write_file(&dir, &long, "x").unwrap();
        let want = format!("sim_{}.svg", "L".repeat(super::MAX_FILE_CHARS - 4));
        assert!(dir.join(&want).is_file(), "{want}");
        let stem = format!("{}_2", super::safe_name(&"L".repeat(300)));
        super::write_file(&dir, &format!("resid_{stem}.svg"), "x").unwrap();
        assert!(dir.join(format!("resid_{stem}.svg")).is_file());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn markdown_cells_keep_their_columns() {
        let mut t = super::Table::new(&["run", "note"]);
        t.row(vec!["a|b".into(), "diverged:\nline two".into()]);
        let md = t.markdown();
        let row = md.lines().nth(2).unwrap();
        assert_eq!(row, "| a\\|b | diverged: line two |");
        // Three unescaped separators: two columns.
        assert_eq!(row.replace("\\|", "").matches('|').count(), 3, "{row}");
    }
}
