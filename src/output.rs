//! Writing results all or nothing: a run's output directory afterwards holds exactly the files of one
//! complete run, or is as it was.
//!
//! Everything is computed first. [`write_dir`] then takes a lock beside the target (`.NAME.lock`, an
//! advisory `flock` the kernel releases when the process dies, so a lock is never stale), writes every file
//! into a private directory beside it (`.NAME.tmp-PID`), and swaps that directory into place: atomically on
//! Linux (`renameat2(RENAME_EXCHANGE)`), elsewhere by two renames with a moment between them in which the
//! target is absent (never mixed). The previous contents are then removed, so a file an earlier run wrote and
//! this one did not (an `evaluation.json`) does not survive beside the new ones. A second run into the same
//! directory while one is writing is refused with a clear line; the leftovers of an interrupted run (its
//! temporary directory) are removed by the next run under the lock.
//!
//! A directory is only replaced when it is empty or holds nothing but what a run writes there (the names
//! the caller lists, and hidden leftovers of an earlier version): `--out ~` must not delete a home directory.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Writes `files` (name, contents) as the whole contents of the directory `dir`; see the module doc. A name
/// may hold subdirectories (`plots/x.png`). An existing `dir` may hold only the top-level names of `files`.
pub fn write_files<N: AsRef<str>>(dir: &Path, files: &[(N, Vec<u8>)]) -> Result<()> {
    write_dir(dir, files, &[])
}

/// [`write_files`], where an existing `dir` may also hold the names in `replaces` (files a run of the same
/// job writes only sometimes, such as `evaluation.json`): they are replaced with the rest.
pub fn write_dir<N: AsRef<str>>(
    dir: &Path,
    files: &[(N, Vec<u8>)],
    replaces: &[&str],
) -> Result<()> {
    let known: Vec<&str> = files
        .iter()
        .map(|(n, _)| top_level(n.as_ref()))
        .chain(replaces.iter().copied())
        .collect();
    let target = Destination::of(dir)?;
    target.check_replaceable(&known)?;
    let _lock = Lock::take(&target)?;
    target.clean_leftovers();
    target.check_replaceable(&known)?;
    let temp = target.sibling(&format!("tmp-{}", std::process::id()));
    let result = write_into(&temp, files).and_then(|()| target.swap_in(&temp));
    if result.is_err() {
        let _ = fs::remove_dir_all(&temp);
    }
    result
}

/// Checks, before a long computation, that [`write_dir`] would accept `dir` (not a file, not a directory of
/// someone else's files); the same check runs again when writing.
pub fn check_dir(dir: &Path, replaces: &[&str]) -> Result<()> {
    Destination::of(dir)?.check_replaceable(replaces)
}

fn write_into<N: AsRef<str>>(temp: &Path, files: &[(N, Vec<u8>)]) -> Result<()> {
    fs::create_dir(temp).map_err(|e| Error::io(temp, e))?;
    for (name, bytes) in files {
        let path = temp.join(name.as_ref());
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        let mut f = fs::File::create(&path).map_err(|e| Error::io(&path, e))?;
        f.write_all(bytes).map_err(|e| Error::io(&path, e))?;
        f.sync_all().map_err(|e| Error::io(&path, e))?;
    }
    Ok(())
}

/// The output directory, split into its parent and its name.
struct Destination {
    path: PathBuf,
    parent: PathBuf,
    name: String,
}

impl Destination {
    fn of(dir: &Path) -> Result<Destination> {
        // `.`, `..` or a trailing `/..` have no name of their own: use the directory they resolve to.
        let resolved = match dir.file_name() {
            Some(_) => dir.to_path_buf(),
            None => dir
                .canonicalize()
                .map_err(|e| out_err(dir, format!("cannot be resolved: {e}")))?,
        };
        let name = file_name(&resolved)?.to_string();
        let parent = parent_of(&resolved);
        Ok(Destination {
            path: resolved,
            parent,
            name,
        })
    }

    /// `.NAME.<what>` beside the target.
    fn sibling(&self, what: &str) -> PathBuf {
        self.parent.join(format!(".{}.{what}", self.name))
    }

    /// Absent, or a directory holding only `known` names and hidden leftovers of an earlier version.
    fn check_replaceable(&self, known: &[&str]) -> Result<()> {
        let meta = match fs::symlink_metadata(&self.path) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(Error::io(&self.path, e)),
        };
        if meta.file_type().is_symlink() {
            return Err(out_err(
                &self.path,
                "is a symbolic link; give the directory it points to",
            ));
        }
        if !meta.is_dir() {
            return Err(out_err(
                &self.path,
                "exists and is a file, not a directory; choose another --out or remove the file",
            ));
        }
        let entries = fs::read_dir(&self.path).map_err(|e| Error::io(&self.path, e))?;
        let mut foreign = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| Error::io(&self.path, e))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            let ours = known.contains(&name.as_str())
                || (name.starts_with('.') && name.ends_with(".partial"));
            if !ours {
                foreign.push(name);
            }
        }
        if foreign.is_empty() {
            return Ok(());
        }
        foreign.sort();
        let more = if foreign.len() > 3 {
            format!(" and {} more", foreign.len() - 3)
        } else {
            String::new()
        };
        foreign.truncate(3);
        Err(out_err(
            &self.path,
            format!(
                "exists and holds files this run does not write ({}{more}); a run replaces its output \
                 directory whole, so give a new or empty directory",
                foreign.join(", ")
            ),
        ))
    }

    /// Removes temporary directories of earlier runs of this target; called under the lock, so none of
    /// them belongs to a live run.
    fn clean_leftovers(&self) {
        for what in ["tmp-", "old-"] {
            let prefix = format!(".{}.{what}", self.name);
            for (path, _) in hidden_with_pid(&self.parent, &prefix) {
                let _ = fs::remove_dir_all(&path);
            }
        }
    }

    /// Puts the finished directory `temp` in place of the target and removes what was there.
    fn swap_in(&self, temp: &Path) -> Result<()> {
        if !self.path.exists() {
            return fs::rename(temp, &self.path).map_err(|e| Error::io(&self.path, e));
        }
        if exchange(temp, &self.path).is_ok() {
            // `temp` now holds the previous contents.
            let _ = fs::remove_dir_all(temp);
            return Ok(());
        }
        let old = self.sibling(&format!("old-{}", std::process::id()));
        fs::rename(&self.path, &old).map_err(|e| Error::io(&self.path, e))?;
        if let Err(e) = fs::rename(temp, &self.path) {
            let _ = fs::rename(&old, &self.path);
            return Err(Error::io(&self.path, e));
        }
        let _ = fs::remove_dir_all(&old);
        Ok(())
    }
}

/// The exclusive right to write a target, held until dropped.
struct Lock {
    path: PathBuf,
    #[cfg(unix)]
    _file: fs::File,
}

impl Lock {
    #[cfg(unix)]
    fn take(target: &Destination) -> Result<Lock> {
        use std::io::Read;
        use std::os::unix::fs::MetadataExt;
        use std::os::unix::io::AsRawFd;

        fs::create_dir_all(&target.parent).map_err(|e| Error::io(&target.parent, e))?;
        let path = target.sibling("lock");
        // A holder removes the lock file before it releases the lock; whoever opened the removed file
        // then holds a lock on nothing and tries again on the new one.
        for _ in 0..100 {
            let mut file = fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(|e| Error::io(&path, e))?;
            // SAFETY: `flock` on a descriptor this function owns; no memory is passed.
            if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
                let e = std::io::Error::last_os_error();
                if e.kind() != std::io::ErrorKind::WouldBlock {
                    return Err(Error::io(&path, e));
                }
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                let who = match holder.trim().parse::<u32>() {
                    Ok(pid) => format!("another run (process {pid})"),
                    Err(_) => "another run".into(),
                };
                return Err(out_err(
                    &target.path,
                    format!(
                        "{who} is writing this directory right now; wait for it to finish or choose \
                         another --out"
                    ),
                ));
            }
            let same = match (file.metadata(), fs::metadata(&path)) {
                (Ok(held), Ok(now)) => held.ino() == now.ino() && held.dev() == now.dev(),
                _ => false,
            };
            if !same {
                continue;
            }
            file.set_len(0).map_err(|e| Error::io(&path, e))?;
            write!(file, "{}", std::process::id()).map_err(|e| Error::io(&path, e))?;
            return Ok(Lock { path, _file: file });
        }
        Err(out_err(
            &target.path,
            "could not take its lock: other runs keep replacing it",
        ))
    }

    /// Without `flock`: the lock file created exclusively, with the holder's process id; a lock whose
    /// process is gone is stale and taken over.
    #[cfg(not(unix))]
    fn take(target: &Destination) -> Result<Lock> {
        fs::create_dir_all(&target.parent).map_err(|e| Error::io(&target.parent, e))?;
        let path = target.sibling("lock");
        for _ in 0..2 {
            match fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
            {
                Ok(mut f) => {
                    write!(f, "{}", std::process::id()).map_err(|e| Error::io(&path, e))?;
                    return Ok(Lock { path });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let pid = fs::read_to_string(&path)
                        .ok()
                        .and_then(|s| s.trim().parse().ok());
                    if pid.is_some_and(process_alive) {
                        return Err(out_err(
                            &target.path,
                            "another run is writing this directory right now; wait for it or choose another --out",
                        ));
                    }
                    let _ = fs::remove_file(&path);
                }
                Err(e) => return Err(Error::io(&path, e)),
            }
        }
        Err(out_err(&target.path, "could not take its lock"))
    }
}

impl Drop for Lock {
    fn drop(&mut self) {
        // Removed while still held (the file closes after this), see `take`.
        let _ = fs::remove_file(&self.path);
    }
}

/// Swaps two paths atomically where the system can.
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        CString::new(p.as_os_str().as_bytes())
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))
    };
    let (a, b) = (c(a)?, c(b)?);
    // SAFETY: two NUL-terminated paths that outlive the call.
    let rc = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            a.as_ptr(),
            libc::AT_FDCWD,
            b.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange(_: &Path, _: &Path) -> std::io::Result<()> {
    Err(std::io::ErrorKind::Unsupported.into())
}

/// Whether process `pid` still runs (assumed so where this cannot be told). Only the lock without `flock`
/// needs it.
#[cfg(not(unix))]
fn process_alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    if cfg!(target_os = "linux") {
        Path::new(&format!("/proc/{pid}")).exists()
    } else {
        true
    }
}

/// Entries of `dir` named `PREFIX<pid>`, with the pid.
fn hidden_with_pid(dir: &Path, prefix: &str) -> Vec<(PathBuf, u32)> {
    let Ok(entries) = fs::read_dir(dir) else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let pid = name.strip_prefix(prefix)?.parse().ok()?;
            Some((e.path(), pid))
        })
        .collect()
}

fn top_level(name: &str) -> &str {
    name.split(['/', '\\']).next().unwrap_or(name)
}

fn file_name(path: &Path) -> Result<&str> {
    path.file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| out_err(path, "has no file name"))
}

fn parent_of(path: &Path) -> PathBuf {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf()
}

fn out_err(path: &Path, message: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("--out {}: {message}", path.display()))
}

/// `value` as `Display` writes it (`value.to_string()`), through ryu where that gives the same text. Both
/// write the shortest digits that read back to `value` and, of those, the ones nearest to it; they differ
/// only where two are equally near (ryu takes the even last digit, `Display` the larger:
/// `-691780342843863.3` against ryu's `.2`). That needs `value`'s exact decimal expansion to end one digit
/// after the shortest digits (at most 17), so ryu is taken only for a value whose expansion has more than 18
/// significant digits ([`exact_digits_exceed_18`]; every value with a full mantissa, as computed ones have).
/// ryu also writes an exponent (`1e16`, `1e-7`) where `Display` writes every zero, and `1.0` where it writes
/// `1`: the rest goes to `Display`, into `fallback`. Property tests hold the two equal.
pub fn display<'a>(value: f64, digits: &'a mut ryu::Buffer, fallback: &'a mut String) -> &'a str {
    if value.is_finite() {
        let text = digits.format_finite(value);
        // ryu writes an exponent only below 1e-5 or from 1e16 on: no need to look for it in between.
        let plain = (1e-4..1e15).contains(&value.abs()) || !text.contains('e');
        if plain && exact_digits_exceed_18(value, text) {
            return text.strip_suffix(".0").unwrap_or(text);
        }
    }
    use std::fmt::Write as _;
    fallback.clear();
    write!(fallback, "{value}").expect("a String takes any text");
    fallback
}

/// Whether finite `value`, written `text` without an exponent, has more than 18 significant digits in its
/// exact decimal expansion. With `k` binary fraction digits (the odd numerator of `value = n / 2^k`) the
/// expansion has exactly `k` decimals, its last a 5; below 1 the first `p` of them are the zeros after the
/// point, so it has `k − p` significant digits, and at least `k + 1` from 1 on.
fn exact_digits_exceed_18(value: f64, text: &str) -> bool {
    let bits = value.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let mantissa = (bits & ((1 << 52) - 1)) | if biased == 0 { 0 } else { 1 << 52 };
    if mantissa == 0 {
        return false;
    }
    let fraction_bits = -(biased.max(1) - 1075 + mantissa.trailing_zeros() as i32);
    if fraction_bits < 19 {
        return false;
    }
    // From 0.1 on (the double nearest 0.1 lies above it, and "0.1" reads back to it) the text has no
    // zeros after the point; most numbers are there.
    if value.abs() >= 0.1 {
        return true;
    }
    let zeros_after_point =
        text.trim_start_matches('-')
            .strip_prefix("0.")
            .map_or(0, |d| d.len() - d.trim_start_matches('0').len()) as i32;
    fraction_bits >= 19 + zeros_after_point
}

/// A CSV file built in memory, numbers written as `Display` writes them (the shortest text that reads back as
/// the same number): through one reused buffer, not a `String` per cell, which cost as much as the digits. A
/// row's cells are gathered and written by [`CsvText::end_row`] at once, the csv crate's fast path for a whole
/// record (the same bytes as a cell at a time, at less than half the cost a cell).
pub struct CsvText {
    name: &'static str,
    writer: csv::Writer<Vec<u8>>,
    row: csv::ByteRecord,
    cell: String,
}

impl CsvText {
    /// A file named `name` (for messages) with the columns `header`.
    pub fn new<H: AsRef<[u8]>>(
        name: &'static str,
        header: impl IntoIterator<Item = H>,
    ) -> Result<CsvText> {
        let mut text = CsvText {
            name,
            // A larger buffer than the crate's 8 kB: fewer rows left to its slow path at the buffer's end.
            writer: csv::WriterBuilder::new()
                .buffer_capacity(1 << 16)
                .from_writer(Vec::new()),
            row: csv::ByteRecord::new(),
            cell: String::with_capacity(32),
        };
        text.writer
            .write_record(header)
            .map_err(|e| text.error(e))?;
        Ok(text)
    }

    /// The next cell of the row, as text (quoted where CSV needs it).
    pub fn text(&mut self, cell: &str) -> Result<()> {
        self.row.push_field(cell.as_bytes());
        Ok(())
    }

    /// The next cell of the row: `value` as `value.to_string()` writes it.
    pub fn number(&mut self, value: f64) -> Result<()> {
        let mut digits = ryu::Buffer::new();
        let cell = display(value, &mut digits, &mut self.cell);
        self.row.push_field(cell.as_bytes());
        Ok(())
    }

    /// Ends the row, and writes it.
    pub fn end_row(&mut self) -> Result<()> {
        self.writer
            .write_byte_record(&self.row)
            .map_err(|e| Error::Invalid(format!("{}: {e}", self.name)))?;
        self.row.clear();
        Ok(())
    }

    /// The file's bytes (its rows ended by [`CsvText::end_row`]).
    pub fn finish(self) -> Result<Vec<u8>> {
        let name = self.name;
        self.writer
            .into_inner()
            .map_err(|e| Error::Invalid(format!("{name}: {e}")))
    }

    fn error(&self, e: csv::Error) -> Error {
        Error::Invalid(format!("{}: {e}", self.name))
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn same_as_display(x: f64) {
        let (mut digits, mut fallback) = (ryu::Buffer::new(), String::new());
        assert_eq!(
            display(x, &mut digits, &mut fallback),
            x.to_string(),
            "{x:?}"
        );
    }

    /// A row written at once (`end_row`) gives the bytes of the crate's writer fed a cell at a time, cells
    /// that need quotes included, whether or not the row fits in what is left of the writer's buffer.
    #[test]
    fn rows_written_at_once_are_the_cells_written_one_by_one() {
        let header = ["id", "x", "note"];
        let mut text = CsvText::new("t.csv", header).unwrap();
        let mut cells = csv::Writer::from_writer(Vec::new());
        cells.write_record(header).unwrap();
        let notes = ["plain", "a, b", "say \"hi\"", "two\nlines", " padded ", "-"];
        for i in 0..3000 {
            let (id, x) = (format!("p{i}"), (i as f64 - 1500.5) / 7.0);
            let note = notes[i % notes.len()].repeat(1 + i % 3 * 50);
            text.text(&id).unwrap();
            text.number(x).unwrap();
            text.text(&note).unwrap();
            text.end_row().unwrap();
            for cell in [id, x.to_string(), note] {
                cells.write_field(cell).unwrap();
            }
            cells.write_record(None::<&[u8]>).unwrap();
        }
        assert_eq!(text.finish().unwrap(), cells.into_inner().unwrap());
    }

    #[test]
    fn a_number_is_written_as_display_writes_it_at_the_edges() {
        for x in [
            0.0,
            -0.0,
            1.0,
            -1.0,
            10.0,
            0.1,
            0.1 + 0.2,
            1e-5,
            1e-4,
            0.00012345678901234567,
            1e15,
            1e16,
            9.999999999999998e15,
            9007199254740993.0,
            1e21,
            1e22,
            123456789012345680.0,
            5e-324,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            f64::EPSILON,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            // Exactly halfway between two shortest candidates: ryu's even digit against Display's larger one.
            -691780342843863.3,
            691780342843863.3,
            1.0 + 2f64.powi(-17) * 0.5,
            0.000244140625,
        ] {
            same_as_display(x);
        }
        let (mut digits, mut fallback) = (ryu::Buffer::new(), String::new());
        for (x, fast) in [
            (0.6038665254990336, true),
            (3.274923269720183, true),
            (0.5, false),
        ] {
            display(x, &mut digits, &mut fallback);
            assert_eq!(fallback.is_empty(), fast, "{x} through ryu: {fast}");
            fallback.clear();
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 20_000, failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn any_number_is_written_as_display_writes_it(
            bits in any::<u64>(),
            v in any::<f64>(),
            near in -10.0..10.0f64,
            scale in -30i32..30,
        ) {
            // Values of few binary digits, whose exact expansions are short: where ties lie.
            let short = (bits >> (bits % 64)) as f64 * 2f64.powi(scale * 2);
            for x in [f64::from_bits(bits), v, near, near * 1e3, near * 10f64.powi(scale), short] {
                same_as_display(x);
            }
        }
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_rerun_replaces_the_whole_directory_and_leaves_nothing_beside_it() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("run");
        write_dir(
            &out,
            &[("a.csv", b"1".to_vec()), ("plots/p.png", b"2".to_vec())],
            &["b.json"],
        )
        .unwrap();
        assert_eq!(names(&out), ["a.csv", "plots"]);
        // A leftover of an interrupted run beside it.
        fs::create_dir(root.path().join(".run.tmp-999999")).unwrap();
        write_dir(&out, &[("b.json", b"3".to_vec())], &["a.csv", "plots"]).unwrap();
        assert_eq!(names(&out), ["b.json"]);
        assert_eq!(names(root.path()), ["run"]);
    }

    #[test]
    fn foreign_files_files_and_directories_are_refused_with_their_reason() {
        let root = tempfile::tempdir().unwrap();
        let home = root.path().join("home");
        fs::create_dir(&home).unwrap();
        fs::write(home.join("thesis.tex"), "x").unwrap();
        let e = write_files(&home, &[("a.csv", vec![])])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("thesis.tex") && e.contains("new or empty"),
            "{e}"
        );
        assert_eq!(names(&home), ["thesis.tex"]);

        let file = root.path().join("f");
        fs::write(&file, "x").unwrap();
        let e = write_files(&file, &[("a.csv", vec![])])
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a file, not a directory"), "{e}");
    }

    #[test]
    fn a_held_lock_refuses_a_second_writer() {
        let root = tempfile::tempdir().unwrap();
        let target = Destination::of(&root.path().join("run")).unwrap();
        let held = Lock::take(&target).unwrap();
        let e = write_files(&target.path, &[("a", vec![])])
            .unwrap_err()
            .to_string();
        assert!(e.contains("is writing this directory right now"), "{e}");
        assert!(!target.path.exists());
        drop(held);
        write_files(&target.path, &[("a", vec![])]).unwrap();
        assert_eq!(names(root.path()), ["run"]);
    }
}
