//! Writing results so that a failed or interrupted run never leaves a half-written file: everything is
//! computed first, each file goes to a temporary name in the target directory, and only when all of them
//! are written are they renamed into place.

use std::fs;
use std::io::Write;
use std::path::Path;

use crate::error::{Error, Result};

/// Writes `files` (name, contents) into `dir`, creating it if needed. A name may hold subdirectories
/// (`plots/x.png`): they are created, and the file's temporary sits next to it.
pub fn write_files<N: AsRef<str>>(dir: &Path, files: &[(N, Vec<u8>)]) -> Result<()> {
    fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let temp_name = |name: &str| {
        let target = dir.join(name);
        let file = target
            .file_name()
            .map_or_else(|| name.into(), |f| f.to_string_lossy().into_owned());
        target.with_file_name(format!(".{file}.partial"))
    };
    let mut written = Vec::new();
    let result = (|| {
        for (name, bytes) in files {
            let temp = temp_name(name.as_ref());
            if let Some(parent) = temp.parent() {
                fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            written.push(temp.clone());
            let mut f = fs::File::create(&temp).map_err(|e| Error::io(&temp, e))?;
            f.write_all(bytes).map_err(|e| Error::io(&temp, e))?;
            f.sync_all().map_err(|e| Error::io(&temp, e))?;
        }
        for (name, _) in files {
            let target = dir.join(name.as_ref());
            fs::rename(temp_name(name.as_ref()), &target).map_err(|e| Error::io(&target, e))?;
        }
        Ok(())
    })();
    if result.is_err() {
        for temp in written {
            let _ = fs::remove_file(temp);
        }
    }
    result
}
