//! Writing artifacts safely: every file FRMD produces goes through [`write_atomic_with`] (a
//! temporary file in the same directory, synced, then renamed over the target, so that a write
//! cut short leaves the previous file intact), and every command checks its outputs with
//! [`check_output_file`] / [`check_output_dir`] before any long work (an existing output is
//! refused unless `force`, an input is never an output, the parent directory must exist or be
//! creatable).
use anyhow::{bail, Context};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The temporary sibling a write of `path` goes through: hidden, with the same extension (some
/// writers pick the format from it).
fn temp_path(path: &Path) -> anyhow::Result<PathBuf> {
    let stem = path
        .file_stem()
        .with_context(|| format!("{}: not a file path", path.display()))?;
    let mut tmp = std::ffi::OsString::from(".");
    tmp.push(stem);
    tmp.push(format!(".tmp-{}", std::process::id()));
    if let Some(ext) = path.extension() {
        tmp.push(".");
        tmp.push(ext);
    }
    Ok(path.with_file_name(tmp))
}

/// Writes `path` atomically: `write(tmp)` fills a temporary file beside it, which is synced
/// and renamed over `path`; on any error the temporary file is removed and `path` is untouched.
/// A missing parent directory is created first.
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&Path) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let tmp = temp_path(path)?;
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("cannot create {}", parent.display()))?;
    }
    let result = write(&tmp).and_then(|()| {
        File::open(&tmp)
            .and_then(|f| f.sync_all())
            .with_context(|| format!("syncing {}", tmp.display()))?;
        std::fs::rename(&tmp, path)
            .with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `bytes` to `path` atomically (see [`write_atomic_with`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    write_atomic_with(path, |tmp| {
        let mut file = File::create(tmp)?;
        file.write_all(bytes)?;
        Ok(())
    })
}

/// True when `a` and `b` name the same existing file or directory.
fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// Creates and removes a probe file in `dir` (permission bits alone do not say what the
/// process may do).
fn probe_writable(dir: &Path) -> anyhow::Result<()> {
    let probe = dir.join(format!(".frmd-write-probe-{}", std::process::id()));
    File::create(&probe)?;
    std::fs::remove_file(&probe)?;
    Ok(())
}

/// The parent directory of `path` must exist as a directory or be creatable (its nearest
/// existing ancestor is a directory).
fn check_parent(path: &Path, option: &str) -> anyhow::Result<()> {
    let mut ancestor = path.parent();
    while let Some(dir) = ancestor {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        if dir.exists() {
            if !dir.is_dir() {
                bail!(
                    "{option} {}: {} is not a directory",
                    path.display(),
                    dir.display()
                );
            }
            return probe_writable(dir).with_context(|| {
                format!(
                    "{option} {}: directory {} is not writable",
                    path.display(),
                    dir.display()
                )
            });
        }
        ancestor = dir.parent();
    }
    Ok(())
}

/// Checks an output file before any work: not one of `inputs` (never, even with `force`), not
/// an existing file unless `force`, not a directory, and in a directory that exists or can be
/// created. `option` names the flag in the error (e.g. `--json`).
pub fn check_output_file(
    path: &Path,
    option: &str,
    force: bool,
    inputs: &[&Path],
) -> anyhow::Result<()> {
    if let Some(input) = inputs.iter().find(|i| same_file(path, i)) {
        bail!("{option} {}: this is the input {}; refusing to overwrite an input (choose another path)", path.display(), input.display());
    }
    if path.is_dir() {
        bail!(
            "{option} {}: is a directory, expected a file path",
            path.display()
        );
    }
    if path.exists() && !force {
        bail!(
            "{option} {}: the file exists; pass --force to replace it",
            path.display()
        );
    }
    check_parent(path, option)
}

/// Checks an output directory before any work: not one of `inputs` and not containing one, not
/// a file, empty or missing unless `force`, and creatable.
pub fn check_output_dir(
    dir: &Path,
    option: &str,
    force: bool,
    inputs: &[&Path],
) -> anyhow::Result<()> {
    if let Some(input) = inputs.iter().find(|i| {
        same_file(dir, i)
            || i.canonicalize()
                .ok()
                .zip(dir.canonicalize().ok())
                .is_some_and(|(i, d)| i.starts_with(d))
    }) {
        bail!("{option} {}: holds the input {}; refusing to write over an input (choose another directory)", dir.display(), input.display());
    }
    if dir.exists() {
        if !dir.is_dir() {
            bail!(
                "{option} {}: is a file, expected a directory",
                dir.display()
            );
        }
        let non_empty = std::fs::read_dir(dir)
            .with_context(|| format!("{option} {}: cannot list it", dir.display()))?
            .next()
            .is_some();
        if non_empty && !force {
            bail!(
                "{option} {}: the directory is not empty; pass --force to write into it",
                dir.display()
            );
        }
        return probe_writable(dir)
            .with_context(|| format!("{option} {}: the directory is not writable", dir.display()));
    }
    check_parent(dir, option)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_keeps_the_old_file_when_the_writer_fails() {
        let dir = std::env::temp_dir().join(format!("frmd-artifact-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.bin");
        write_atomic(&path, b"old").unwrap();
        let err = write_atomic_with(&path, |tmp| {
            std::fs::write(tmp, b"half")?;
            bail!("disk full")
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            1,
            "temporary file left behind"
        );
        assert!(check_output_file(&path, "--out", false, &[]).is_err());
        assert!(check_output_file(&path, "--out", true, &[]).is_ok());
        assert!(check_output_file(&path, "--out", true, &[&path]).is_err());
        assert!(check_output_dir(&dir, "--out", false, &[]).is_err());
        assert!(check_output_file(&dir.join("missing/x.json"), "--json", false, &[]).is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
