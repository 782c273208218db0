//! The `ctsid` command line. Each subcommand lives in `src/cli/<name>.rs`; errors print as one
//! line on standard error and the process exits non-zero.

/// `eprintln!` that a closed standard error cannot stop: the standard macro panics when the
/// write fails (`ctsid regress ... 2>&1 | head -1` exited 101 at its first note). Defined
/// before the modules, so every `eprintln!` of the command line is this one.
macro_rules! eprintln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

mod cli;

use clap::Parser;

fn main() {
    let code = match cli::Cli::try_parse() {
        Ok(args) => match cli::run(args) {
            Ok(()) => 0,
            Err(e) => {
                // One line even when a header or run id from the data carries a line break, and
                // no raw control bytes from the data (a NUL cut the line in a terminal, an ESC
                // sequence recoloured it): each is shown escaped.
                let text = one_line(&e.to_string());
                // Bounded whatever a message carries from the data (names, fields, run ids).
                let text = ctsid::util::clip(&text, 2000);
                eprintln!("error: {text}");
                2
            }
        },
        Err(e) => usage_error(e),
    };
    std::process::exit(code);
}

/// `text` with every control character escaped (`\n`, `\r`, `\t`, `\0`, `\u{1b}`): a message
/// quoting data stays one printable line.
fn one_line(text: &str) -> String {
    text.chars()
        .map(|c| match c {
            '\n' => "\\n".to_string(),
            '\r' => "\\r".to_string(),
            '\0' => "\\0".to_string(),
            c if c.is_control() => c.escape_default().to_string(),
            c => c.to_string(),
        })
        .collect()
}

/// Help and version go out as clap renders them; a usage error becomes one line: clap's first
/// line, its tip if it has one, and where to read more.
fn usage_error(e: clap::Error) -> i32 {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        let _ = e.print();
        return if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand {
            2
        } else {
            0
        };
    }
    let text = e.render().to_string();
    let mut lines = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .peekable();
    let mut first = lines
        .next()
        .unwrap_or("error: invalid arguments")
        .to_string();
    // "the following required arguments were not provided:" lists them on the next lines.
    if first.ends_with(':') {
        let mut items = Vec::new();
        while let Some(l) = lines.next_if(|l| !l.starts_with("Usage:") && !l.starts_with("tip:")) {
            items.push(l);
        }
        first = format!("{} {}", first, items.join(", "));
    }
    let tip = lines
        .find_map(|l| l.strip_prefix("tip:"))
        .map(|t| {
            // clap suggests `-- -1`, which ends the options; a negative value of an option is
            // written `--tau=-1`.
            if t.contains("as a value, use '--") {
                " (a negative value is written with '=', like --tau=-1)".to_string()
            } else {
                format!(" ({})", t.trim())
            }
        })
        .unwrap_or_default();
    let first = if first.starts_with("error:") {
        first
    } else {
        format!("error: {first}")
    };
    eprintln!("{first}{tip}; see --help");
    2
}
