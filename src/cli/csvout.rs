//! Writing a CSV file back with extra columns beside the input's, in the file's row order.
//!
//! `derive` and `simulate` read their data through [`RecordSet`], which groups rows into runs
//! and remembers each sample's CSV row; this maps every row back to its (run, sample) so the
//! output keeps the input's rows and columns untouched.

use ctsid::records::RecordSet;
use ctsid::{Error, Result};
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

/// Checks, before any work, what [`write_with_columns`] needs: an output (when given) that is
/// none of the inputs, in a folder that exists; and an input it can read a second time, to copy
/// its rows (a pipe or a device would give them only once, and the output would lose them).
/// `what` names the command in the message. With the `names` of the columns to append, also
/// refuses a file that has one of them already (found before the work, not after it).
pub fn check(
    input: &Path,
    output: Option<&Path>,
    other_inputs: &[&Path],
    names: &[String],
    what: &str,
) -> Result<()> {
    if let Some(o) = output {
        let mut inputs = vec![input];
        inputs.extend_from_slice(other_inputs);
        super::check_output_file(o, &inputs)?;
    }
    match std::fs::metadata(input) {
        Ok(m) if !m.is_file() => Err(Error::Io {
            path: input.display().to_string(),
            message: format!(
                "{what} reads its input twice (to copy its rows): give a regular file, not a pipe or a device"
            ),
        }),
        // A header that cannot be read is the loader's to report, with its own message.
        Ok(_) => match read_header(input) {
            Ok(header) => refuse_clash(input, &header, names),
            Err(_) => Ok(()),
        },
        Err(_) => Ok(()),
    }
}

fn read_header(input: &Path) -> Result<Vec<String>> {
    open_with_header(input).map(|(_, h)| h)
}

/// A reader of `input` past its header, and the header.
fn open_with_header(input: &Path) -> Result<(csv::Reader<std::fs::File>, Vec<String>)> {
    let p = input.display().to_string();
    let mut rdr = csv::Reader::from_path(input).map_err(|e| Error::Io {
        path: p.clone(),
        message: e.to_string(),
    })?;
    let header = rdr
        .headers()
        .map_err(|e| Error::Csv {
            path: p,
            row: 1,
            message: e.to_string(),
        })?
        .iter()
        .map(String::from)
        .collect();
    Ok((rdr, header))
}

/// Refuses appending a column named like one of `header` (trimmed, as the loader reads it:
/// ` y_d1` is the column `y_d1`).
fn refuse_clash(input: &Path, header: &[String], names: &[String]) -> Result<()> {
    match names
        .iter()
        .find(|n| header.iter().any(|h| h.trim() == n.as_str()))
    {
        Some(n) => Err(Error::InvalidData(format!(
            "{}: already has a column '{n}'; rename it or write elsewhere",
            input.display()
        ))),
        None => Ok(()),
    }
}

/// Copies `input` to `output` (standard output when `None`) with the columns `names` appended;
/// `cell(run, sample, k)` gives column k's text for a row. Extra names that already exist in
/// the file are refused.
pub fn write_with_columns(
    input: &Path,
    output: Option<&Path>,
    rs: &RecordSet,
    names: &[String],
    cell: impl Fn(usize, usize, usize) -> String,
) -> Result<()> {
    let mut at = HashMap::new();
    for (r, run) in rs.runs.iter().enumerate() {
        for (i, &row) in run.rows.iter().enumerate() {
            at.insert(row, (r, i));
        }
    }
    let p = input.display().to_string();
    let (mut rdr, mut header) = open_with_header(input)?;
    refuse_clash(input, &header, names)?;
    let out_name = output.map_or("standard output".to_string(), |o| o.display().to_string());
    // A file is written whole or not at all (Ctrl-C on a long write leaves the old one).
    let mut file = output.map(ctsid::util::AtomicFile::create).transpose()?;
    let sink: Box<dyn Write + '_> = match file.as_mut() {
        Some(f) => Box::new(f),
        None => Box::new(std::io::stdout().lock()),
    };
    let mut w = csv::Writer::from_writer(sink);
    let io = |e: csv::Error| Error::Io {
        path: out_name.clone(),
        message: e.to_string(),
    };
    header.extend(names.iter().cloned());
    w.write_record(&header).map_err(io)?;
    for (idx, rec) in rdr.records().enumerate() {
        let row = idx + 2;
        let rec = rec.map_err(|e| Error::Csv {
            path: p.clone(),
            row,
            message: e.to_string(),
        })?;
        let mut fields: Vec<String> = rec.iter().map(String::from).collect();
        match at.get(&row) {
            Some(&(r, i)) => fields.extend((0..names.len()).map(|k| cell(r, i, k))),
            None => fields.extend(names.iter().map(|_| String::new())),
        }
        w.write_record(&fields).map_err(io)?;
    }
    w.flush().map_err(|e| Error::Io {
        path: out_name.clone(),
        message: e.to_string(),
    })?;
    drop(w);
    file.map_or(Ok(()), |f| f.commit())
}
