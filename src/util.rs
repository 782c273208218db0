//! Small checks shared by the modules that validate their input, and number formatting for
//! messages.

use crate::error::{Error, Result};

/// The first element equal to an earlier one: (index of the earlier, index of the repeat).
/// Linear in the length: the run lists it checks can hold a run per row of a large file
/// (`--run-column t` by mistake), where comparing each with all before it took hours.
pub(crate) fn first_repeat<T: Eq + std::hash::Hash>(v: &[T]) -> Option<(usize, usize)> {
    let mut seen = std::collections::HashMap::with_capacity(v.len());
    v.iter()
        .enumerate()
        .find_map(|(j, x)| seen.insert(x, j).map(|i| (i, j)))
}

/// A setting that must be a finite number >= 0.
pub(crate) fn finite_nonneg(name: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Error::param(
            name,
            format!("{v:?}; give a finite number >= 0"),
        ))
    }
}

/// `x` with four decimals where that reads well (1e-3 <= |x| < 1e6, or 0), else in scientific
/// notation with four: a rate of 1e160 rad/s is not 161 digits.
pub fn num4(x: f64) -> String {
    if x == 0.0 || (1e-3..1e6).contains(&x.abs()) {
        format!("{x:.4}")
    } else {
        format!("{x:.4e}")
    }
}

/// A number as the user typed it where that is short (0.02, 1.5, -9999), in scientific
/// notation from 1e7 and below 1e-4 in magnitude (1e300, not 301 digits).
pub fn short(x: f64) -> String {
    if x == 0.0 || (1e-4..1e7).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// Whether a name reads as a number to the expression parser (digits, a point or a sign first,
/// and a valid f64): such a channel could not be told from a constant. `inf` and `nan`, which
/// `f64` parses but the parser reads as names, are names.
pub fn reads_as_number(name: &str) -> bool {
    let t = name.trim();
    t.starts_with(|c: char| c.is_ascii_digit() || matches!(c, '.' | '+' | '-'))
        && t.parse::<f64>().is_ok()
}

/// Why a name that [`reads_as_number`] is refused (the basis, identify and model files say it).
pub const READS_AS_NUMBER: &str =
    "reads as a number, which terms and expressions cannot tell from a constant";

/// Why a name cannot stand for a variable in a model, if it cannot: it reads as a number
/// ([`reads_as_number`]) or as a non-finite value (`nan`, `inf`, `infinity` in any case:
/// `0.12*nan` reads as a broken coefficient). Model files are held to this.
pub fn name_fault(name: &str) -> Option<&'static str> {
    if reads_as_number(name) {
        return Some(READS_AS_NUMBER);
    }
    if ["nan", "inf", "infinity"].contains(&name.to_ascii_lowercase().as_str()) {
        return Some("reads as a non-finite number in the printed equations");
    }
    None
}

/// [`name_fault`], and a name that is not one name to the expression parser (letters, digits
/// and `_`, not a digit first: `y^2` printed as `0.3*y^2` reads as a power, `force [N]` cannot
/// be named in a term). New models are held to this (`identify` refuses such channels); model
/// files written before it keep loading.
pub fn channel_name_fault(name: &str) -> Option<&'static str> {
    if let Some(why) = name_fault(name) {
        return Some(why);
    }
    let mut chars = name.chars();
    let first_ok = chars.next().is_some_and(|c| c.is_alphabetic() || c == '_');
    if !first_ok || !chars.all(|c| c.is_alphanumeric() || c == '_') {
        return Some("is not one name to the expression parser (letters, digits and '_', not a digit first): it would print ambiguously in equations and could not be named in a term");
    }
    None
}

/// [`channel_name_fault`] as the error of the setting `what` that names the channel, which the
/// user is told to rename (`channel`, `column`).
pub fn check_channel_name(name: &str, what: &str, rename: &str) -> crate::Result<()> {
    match channel_name_fault(name) {
        Some(why) => Err(crate::Error::param(
            what,
            format!("'{}' {why}; rename the {rename}", clip(name, 40)),
        )),
        None => Ok(()),
    }
}

/// A file written whole or not at all: the bytes go to a temporary file in the target's folder
/// (`.ctsid-PID-N.tmp`, short whatever the target's name), renamed over the target by
/// [`AtomicFile::commit`]. Dropped without a commit (an error on the way), the temporary file is
/// removed and the target is untouched; a process killed half way leaves the target as it was
/// (and the temporary file beside it). A symbolic link is followed (the file it names is
/// replaced, the link kept), an existing file's permissions are kept, and a target that is not a
/// regular file (a device, a pipe, a socket) is refused: renaming over it would replace it.
pub struct AtomicFile {
    target: std::path::PathBuf,
    tmp: std::path::PathBuf,
    file: Option<std::io::BufWriter<std::fs::File>>,
}

impl AtomicFile {
    /// Creates the temporary file beside `target` (see [`output_target`] for what is refused).
    /// Errors when the temporary file cannot be created (a missing folder, no write permission).
    pub fn create(target: &std::path::Path) -> crate::Result<AtomicFile> {
        let io = |e: std::io::Error| crate::Error::file(target.display().to_string(), e);
        let given = target;
        let target = output_target(target)?;
        // A report's own file names are not checked against the command's inputs up front
        // (`simulate rep/sim_0_y.svg rep/report.md --report rep` replaced both inputs).
        if Outputs::was_read(&target) {
            return Err(crate::Error::Io {
                path: given.display().to_string(),
                message: "is a file this command read; writing it would destroy an input, so write elsewhere".into(),
            });
        }
        let mode = std::fs::metadata(&target).ok().map(|m| m.permissions());
        let (tmp, file) = Self::fresh(&target, mode).map_err(io)?;
        Ok(AtomicFile {
            target,
            tmp,
            file: Some(std::io::BufWriter::new(file)),
        })
    }

    /// A temporary file beside `target` that did not exist before (`create_new`: two writers,
    /// even two processes of the same id in containers sharing a folder, never share one), with
    /// the replaced file's permissions where there was one (on unix, set at creation and again
    /// on the open file, so that no moment has wider ones; special bits left out).
    fn fresh(
        target: &std::path::Path,
        mode: Option<std::fs::Permissions>,
    ) -> std::io::Result<(std::path::PathBuf, std::fs::File)> {
        static SEQ: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let mut opts = std::fs::OpenOptions::new();
        opts.write(true).create_new(true);
        #[cfg(unix)]
        let bits = mode.as_ref().map(|m| {
            use std::os::unix::fs::PermissionsExt;
            m.mode() & 0o777
        });
        #[cfg(unix)]
        if let Some(b) = bits {
            use std::os::unix::fs::OpenOptionsExt;
            opts.mode(b);
        }
        #[cfg(not(unix))]
        let _ = mode;
        let mut last = None;
        for _ in 0..16 {
            let seq = SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.subsec_nanos());
            let name = format!(".ctsid-{}-{seq}-{nanos:08x}.tmp", std::process::id());
            let tmp = target.with_file_name(name);
            match opts.open(&tmp) {
                Ok(file) => {
                    #[cfg(unix)]
                    if let Some(b) = bits {
                        use std::os::unix::fs::PermissionsExt;
                        // The creation mode passed through the umask; the file's own is exact.
                        let _ = file.set_permissions(std::fs::Permissions::from_mode(b));
                    }
                    return Ok((tmp, file));
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.expect("sixteen tries"))
    }

    /// Flushes and renames the temporary file over the target; while an [`Outputs`] is open on
    /// this thread, the rename waits for [`Outputs::commit`]. Errors when the flush, the sync to
    /// disk or the rename fails; the target is then left as it was.
    pub fn commit(mut self) -> crate::Result<()> {
        let file = self.file.take().expect("committed once");
        let done = file
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|f| f.sync_all())
            .and_then(|_| match Outputs::stage(&self.tmp, &self.target) {
                true => Ok(()),
                false => std::fs::rename(&self.tmp, &self.target),
            });
        // The file was taken out of `self`, so `Drop` would leave the temporary file behind on
        // any of these failures (only the rename's was handled, unlike what the type promises).
        done.map_err(|e| {
            let _ = std::fs::remove_file(&self.tmp);
            crate::Error::file(self.target.display().to_string(), e)
        })
    }
}

impl std::io::Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.as_mut().expect("open until committed").write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.file.as_mut().expect("open until committed").flush()
    }
}

/// The files one command writes, renamed into place all together or not at all.
///
/// While an `Outputs` is open on a thread, every [`AtomicFile`] that thread commits (so every
/// model file, CSV and report figure ctsid writes) is written and synced to its temporary file
/// beside the target, and renamed over the target only by [`Outputs::commit`]. Dropped without a
/// commit (the command failed on the way: a report folder that cannot be written after the
/// model file was done), it removes those temporary files, and no target is touched. Without an
/// open `Outputs`, files are renamed as they are committed. While it is open, a file read
/// through [`open_regular`] (records, model files, references) cannot be an output: its
/// [`AtomicFile::create`] is refused.
///
/// A later `begin` on a thread that has one open joins it (only the first commits). Renames are
/// the last step and can still fail one by one (a full file system fails earlier, at the
/// write or the sync); the error then names the first target not replaced, and the files
/// renamed before it stay.
///
/// ```
/// let dir = std::env::temp_dir().join(format!("ctsid-outputs-doc-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// {
///     let _outputs = ctsid::util::Outputs::begin();
///     ctsid::util::write_atomic(&dir.join("model.json"), b"{}")?;
///     // An error here returns before the commit: model.json is not written.
/// }
/// assert!(!dir.join("model.json").exists());
/// let outputs = ctsid::util::Outputs::begin();
/// ctsid::util::write_atomic(&dir.join("model.json"), b"{}")?;
/// outputs.commit()?;
/// assert!(dir.join("model.json").exists());
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct Outputs {
    /// Whether this one opened the thread's staging (a nested `begin` only joins it).
    owner: bool,
    /// Thread-bound: the staging lives in a thread local.
    _local: std::marker::PhantomData<*const ()>,
}

/// What an open [`Outputs`] holds: the staged files (temporary file, target) and the files the
/// command has read ([`open_regular`]), which none of its outputs may replace.
#[derive(Default)]
struct Staging {
    files: Vec<(std::path::PathBuf, std::path::PathBuf)>,
    inputs: Vec<FileId>,
    /// Folders created for the outputs, removed again (when empty) if the command fails.
    folders: Vec<std::path::PathBuf>,
}

/// A file's identity across names (hard and symbolic links): device and inode on unix, the
/// canonical path elsewhere.
#[derive(PartialEq)]
struct FileId(
    #[cfg(unix)] (u64, u64),
    #[cfg(not(unix))] std::path::PathBuf,
);

impl FileId {
    fn of(path: &std::path::Path) -> Option<FileId> {
        #[cfg(unix)]
        {
            use std::os::unix::fs::MetadataExt;
            std::fs::metadata(path)
                .ok()
                .map(|m| FileId((m.dev(), m.ino())))
        }
        #[cfg(not(unix))]
        {
            path.canonicalize().ok().map(FileId)
        }
    }
}

/// Whether two existing paths are one file (hard and symbolic links included); false where
/// either cannot be read.
pub fn same_file(a: &std::path::Path, b: &std::path::Path) -> bool {
    matches!((FileId::of(a), FileId::of(b)), (Some(x), Some(y)) if x == y)
}

thread_local! {
    /// The staging of this thread's outputs, while an [`Outputs`] is open on it.
    static STAGED: std::cell::RefCell<Option<Staging>> = const { std::cell::RefCell::new(None) };
}

impl Outputs {
    /// Opens the staging of this thread's outputs (see the type's docs).
    pub fn begin() -> Outputs {
        let owner = STAGED.with(|s| {
            let mut s = s.borrow_mut();
            let fresh = s.is_none();
            if fresh {
                *s = Some(Staging::default());
            }
            fresh
        });
        Outputs {
            owner,
            _local: std::marker::PhantomData,
        }
    }

    /// Keeps `tmp` for `target` where an `Outputs` is open on this thread; false where none is.
    fn stage(tmp: &std::path::Path, target: &std::path::Path) -> bool {
        STAGED.with(|s| match s.borrow_mut().as_mut() {
            Some(st) => {
                st.files.push((tmp.to_path_buf(), target.to_path_buf()));
                true
            }
            None => false,
        })
    }

    /// Notes, where an `Outputs` is open on this thread, that the command read `path`.
    fn read(path: &std::path::Path) {
        STAGED.with(|s| {
            if let (Some(st), Some(id)) = (s.borrow_mut().as_mut(), FileId::of(path)) {
                st.inputs.push(id);
            }
        })
    }

    /// Whether `target` is a file this thread's open `Outputs` has seen read.
    pub fn was_read(target: &std::path::Path) -> bool {
        STAGED.with(|s| match (s.borrow().as_ref(), FileId::of(target)) {
            (Some(st), Some(id)) => st.inputs.contains(&id),
            _ => false,
        })
    }

    /// Creates the folder `dir` (and missing parents) for outputs; where an `Outputs` is open on
    /// this thread and the command fails, the folders it created are removed again if empty.
    pub fn create_folder(dir: &std::path::Path) -> std::io::Result<()> {
        let mut missing = Vec::new();
        let mut p = Some(dir);
        while let Some(d) = p.filter(|d| !d.as_os_str().is_empty() && !d.exists()) {
            missing.push(d.to_path_buf());
            p = d.parent();
        }
        std::fs::create_dir_all(dir)?;
        STAGED.with(|s| {
            if let Some(st) = s.borrow_mut().as_mut() {
                st.folders.extend(missing);
            }
        });
        Ok(())
    }

    /// The staging, for the `Outputs` that opened it (a joined one has nothing to commit).
    fn take_all(&self) -> Option<Staging> {
        if !self.owner {
            return None;
        }
        STAGED.with(|s| s.borrow_mut().take())
    }

    /// Renames every staged file over its target, in the order they were written (a target
    /// written twice gets the later one). Errors when a rename fails, naming its target; the
    /// staged files after it are removed.
    pub fn commit(self) -> crate::Result<()> {
        let mut list = self
            .take_all()
            .map(|st| st.files)
            .unwrap_or_default()
            .into_iter();
        while let Some((tmp, target)) = list.next() {
            if let Err(e) = std::fs::rename(&tmp, &target) {
                let _ = std::fs::remove_file(&tmp);
                list.for_each(|(t, _)| {
                    let _ = std::fs::remove_file(t);
                });
                return Err(crate::Error::file(target.display().to_string(), e));
            }
        }
        Ok(())
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        if let Some(st) = self.take_all() {
            for (tmp, _) in st.files {
                let _ = std::fs::remove_file(tmp);
            }
            // Innermost first (each was recorded before its parents); a folder that holds
            // anything else stays.
            for d in st.folders {
                let _ = std::fs::remove_dir(d);
            }
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// The file an output to `path` replaces: `path` itself, or the file a chain of symbolic links
/// names (which may not exist yet). Refuses a path with no file name (`/`, one ending in `..`)
/// or with a NUL byte, a name longer than file systems allow, a link into a folder that does not
/// exist, and a target that is not a regular file (a device, a pipe, a socket, a folder), which
/// [`AtomicFile`] would otherwise replace by a file.
pub fn output_target(path: &std::path::Path) -> crate::Result<std::path::PathBuf> {
    // A NUL byte is shown escaped: written as it is, it cut the message in a terminal.
    let err = |message: &str| crate::Error::Io {
        path: path.display().to_string().replace('\0', "\\0"),
        message: message.into(),
    };
    let name = path.file_name().ok_or_else(|| err("not a file name"))?;
    if path.as_os_str().as_encoded_bytes().contains(&0) {
        return Err(err("has a NUL byte, which no file name can hold"));
    }
    // `file_name` reads `out/` as `out`: the write then failed with the system's bare "Not a
    // directory".
    let text = path.as_os_str().as_encoded_bytes();
    if text.ends_with(b"/") || text.ends_with(std::path::MAIN_SEPARATOR_STR.as_bytes()) {
        return Err(err(
            "names a folder (it ends in a separator); give a file name",
        ));
    }
    #[cfg(windows)]
    let units = {
        use std::os::windows::ffi::OsStrExt;
        name.encode_wide().count()
    };
    #[cfg(not(windows))]
    let units = name.len();
    if units > 255 {
        return Err(err(
            "the file name is longer than 255 bytes (units on Windows); give a shorter one",
        ));
    }
    // What the path names, through any links: a pipe behind `/dev/stdout`, a device, a folder.
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => return Err(err("is a folder; give a file name")),
        Ok(m) if !m.is_file() => {
            return Err(err(
                "is not a regular file (a device, a pipe or a socket); give a file name",
            ))
        }
        _ => {}
    }
    let mut target = path.to_path_buf();
    // Links followed by hand (a link may name a file still to be written, which
    // `canonicalize` refuses), relative ones from their own folder, at most 40 in a chain.
    for _ in 0..40 {
        match std::fs::symlink_metadata(&target) {
            Ok(m) if m.file_type().is_symlink() => {
                let next = std::fs::read_link(&target)
                    .map_err(|_| err("is a symbolic link that cannot be read"))?;
                target = match target.parent() {
                    Some(dir) if next.is_relative() => dir.join(next),
                    _ => next,
                };
            }
            _ => {
                let folder = target.parent().filter(|p| !p.as_os_str().is_empty());
                match folder.filter(|f| !f.is_dir()) {
                    None => return Ok(target),
                    Some(f) if target != path => {
                        return Err(err(&format!(
                            "is a symbolic link to {}, whose folder {} does not exist",
                            target.display(),
                            f.display()
                        )))
                    }
                    Some(f) if f.exists() => {
                        return Err(err(&format!("{} is a file, not a folder", f.display())))
                    }
                    Some(f) => {
                        return Err(err(&format!(
                            "folder {} does not exist; create it or write elsewhere",
                            f.display()
                        )))
                    }
                }
            }
        }
    }
    Err(err("is a chain of more than 40 symbolic links"))
}

/// Writes `bytes` to `path` whole or not at all ([`AtomicFile`]). Errors as [`AtomicFile::create`]
/// and [`AtomicFile::commit`] do, and when the write fails.
pub fn write_atomic(path: &std::path::Path, bytes: &[u8]) -> crate::Result<()> {
    use std::io::Write;
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes)
        .map_err(|e| crate::Error::file(path.display().to_string(), e))?;
    f.commit()
}

#[cfg(test)]
mod atomic_tests {
    use super::*;
    use std::io::Write;

    /// A fresh folder of this test process under the system's temporary folder.
    fn scratch(tag: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("ctsid-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Output names that were refused with the wrong reason (the tenth reading): a missing
    /// folder as "a symbolic link ... whose folder does not exist", a trailing separator as the
    /// system's bare "Not a directory", a NUL byte written into the message.
    #[test]
    fn output_names_are_refused_with_their_reason() {
        let base = scratch("targets");
        let file = base.join("plain.txt");
        std::fs::write(&file, "x").unwrap();
        let why = |p: std::path::PathBuf| output_target(&p).unwrap_err().to_string();
        let e = why(base.join("nodir").join("x.json"));
        assert!(
            e.contains("nodir does not exist") && !e.contains("link"),
            "{e}"
        );
        let e = why(file.join("x.json"));
        assert!(e.contains("plain.txt is a file, not a folder"), "{e}");
        let e = why(base.join("newdir/"));
        assert!(e.contains("ends in a separator"), "{e}");
        let e = why(base.join("a\0b.json"));
        assert!(e.contains("a\\0b.json") && !e.contains('\0'), "{e}");
        #[cfg(unix)]
        {
            let link = base.join("dangling.json");
            let _ = std::fs::remove_file(&link);
            std::os::unix::fs::symlink(base.join("gone").join("t.json"), &link).unwrap();
            let e = why(link);
            assert!(
                e.contains("symbolic link") && e.contains("gone does not exist"),
                "{e}"
            );
        }
        std::fs::remove_dir_all(&base).ok();
    }

    /// Folders created for a command's outputs go again when it fails, unless something else
    /// was put in them.
    #[test]
    fn folders_of_a_failed_command_are_removed() {
        let base = scratch("folders");
        {
            let _outputs = Outputs::begin();
            Outputs::create_folder(&base.join("a").join("b")).unwrap();
            write_atomic(&base.join("a").join("b").join("f.txt"), b"x").unwrap();
        }
        assert!(!base.join("a").exists());
        {
            let _outputs = Outputs::begin();
            Outputs::create_folder(&base.join("c")).unwrap();
            std::fs::write(base.join("c").join("own.txt"), "kept").unwrap();
        }
        assert!(base.join("c").join("own.txt").exists());
        let outputs = Outputs::begin();
        Outputs::create_folder(&base.join("d")).unwrap();
        write_atomic(&base.join("d").join("f.txt"), b"x").unwrap();
        outputs.commit().unwrap();
        assert!(base.join("d").join("f.txt").exists());
        std::fs::remove_dir_all(&base).ok();
    }

    #[test]
    fn a_file_is_replaced_whole_or_left_as_it_was() {
        let dir = scratch("atomic");
        let p = dir.join("out.csv");
        std::fs::write(&p, "old").unwrap();
        // An error half way (the writer dropped without commit): the old content stays, no
        // temporary file is left.
        {
            let mut f = AtomicFile::create(&p).unwrap();
            f.write_all(b"new, half").unwrap();
        }
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        write_atomic(&p, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "new");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A link is followed (its file replaced, the link kept), a file's permissions are kept, a
    /// pipe and a device are refused (they were replaced by regular files), and a name as long as
    /// file systems allow is written (the temporary name was the target's and longer).
    #[cfg(unix)]
    #[test]
    fn links_permissions_devices_and_long_names() {
        use std::os::unix::fs::{symlink, PermissionsExt};
        let dir = scratch("atomic-kinds");
        let file = dir.join("target.csv");
        std::fs::write(&file, "old").unwrap();
        // A mode with an execute bit, which no new file gets from any umask.
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o751)).unwrap();
        let link = dir.join("link.csv");
        symlink("target.csv", &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "new");
        let mode = std::fs::metadata(&file).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o751);

        // A link set up before its file exists is followed; one into a missing folder is not.
        let ahead = dir.join("latest.csv");
        symlink(dir.join("run1.csv"), &ahead).unwrap();
        write_atomic(&ahead, b"first").unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.join("run1.csv")).unwrap(),
            "first"
        );
        let dangling = dir.join("dangling.csv");
        symlink(dir.join("missing/x.csv"), &dangling).unwrap();
        let e = write_atomic(&dangling, b"x").unwrap_err().to_string();
        assert!(e.contains("symbolic link") && e.contains("folder"), "{e}");

        for special in [std::path::PathBuf::from("/dev/null"), dir.join("fifo")] {
            if special.starts_with(&dir) {
                let ok = std::process::Command::new("mkfifo").arg(&special).status();
                if !ok.is_ok_and(|s| s.success()) {
                    continue;
                }
            }
            let e = write_atomic(&special, b"x").unwrap_err().to_string();
            assert!(e.contains("not a regular file"), "{e}");
            assert!(!std::fs::metadata(&special).unwrap().is_file());
        }

        let long = dir.join("a".repeat(251) + ".csv");
        write_atomic(&long, b"long").unwrap();
        assert_eq!(std::fs::read_to_string(&long).unwrap(), "long");
        let e = write_atomic(&dir.join("a".repeat(256)), b"x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("longer than 255"), "{e}");
        // A NUL byte: refused before anything is written (the whole output was left beside it
        // under the temporary name when the rename failed).
        let before = std::fs::read_dir(&dir).unwrap().count();
        let e = write_atomic(&dir.join("x\0y.json"), b"x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("NUL"), "{e}");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), before);
        std::fs::remove_dir_all(&dir).ok();
    }
}

/// Opens `path` for reading when it is a regular file of at most `max_bytes` (if given): a
/// folder, a pipe or a device (`/dev/zero` never ends, a FIFO without a writer never answers)
/// is refused before it is opened, with a message that says which it is. A missing or unreadable
/// path and a file larger than `max_bytes` are refused too.
pub fn open_regular(
    path: &std::path::Path,
    max_bytes: Option<u64>,
) -> crate::Result<std::fs::File> {
    let err = |message: String| crate::Error::Io {
        path: path.display().to_string(),
        message,
    };
    let file_err = |e: std::io::Error| crate::Error::file(path.display().to_string(), e);
    let m = std::fs::metadata(path).map_err(file_err)?;
    if m.is_dir() {
        return Err(err("is a folder; give a file".into()));
    }
    if !m.is_file() {
        return Err(err(
            "is a pipe, a socket or a device, not a regular file; save the data to a file first"
                .into(),
        ));
    }
    if let Some(max) = max_bytes.filter(|&max| m.len() > max) {
        return Err(err(format!(
            "is {} bytes; a file of this kind is at most {max}",
            m.len()
        )));
    }
    let file = std::fs::File::open(path).map_err(file_err)?;
    Outputs::read(path);
    Ok(file)
}

#[cfg(test)]
mod open_tests {
    #[test]
    fn folders_devices_and_oversized_files_are_refused_up_front() {
        let dir = std::env::temp_dir();
        let e = super::open_regular(&dir, None).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        let dev = std::path::Path::new("/dev/zero");
        if dev.exists() {
            let e = super::open_regular(dev, None).unwrap_err().to_string();
            assert!(e.contains("not a regular file"), "{e}");
        }
        let p = dir.join(format!("ctsid-open-{}", std::process::id()));
        std::fs::write(&p, "12345").unwrap();
        assert!(super::open_regular(&p, Some(5)).is_ok());
        let e = super::open_regular(&p, Some(4)).unwrap_err().to_string();
        assert!(e.contains("at most 4"), "{e}");
        std::fs::remove_file(&p).ok();
    }
}

/// `s` cut to at most `max` characters for an error message, the cut said with the length
/// (a 20 MB field was echoed whole into a one-line error).
pub fn clip(s: &str, max: usize) -> String {
    let n = s.chars().count();
    if n <= max {
        return s.to_string();
    }
    let head: String = s.chars().take(max).collect();
    format!("{head}... ({n} characters)")
}
