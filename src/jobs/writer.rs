//! Jobs — the writer. In: a job's [`Product`]s and the output folder. Out: the files
//! `<out>/<job>/<product>`, written as a set by [`write_all_atomic`] (each to a temporary file
//! beside it; only when all are written are they renamed into place, so a run that fails or is
//! killed while writing leaves the earlier files as they were and never a partial file under a
//! final name), and their manifest records (SHA-256 and size).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::Product;
use super::manifest::OutputRecord;
use crate::output::{WriteError, write_all_atomic};

/// Write `products` into `<out_dir>/<job>/`, all or none of them (see [`write_all_atomic`]);
/// returns each file's record keyed by its path relative to `out_dir` (`<job>/<product>`, with
/// `/` separators).
pub fn write_job_products(
    out_dir: &Path,
    job: &str,
    products: &[Product],
) -> Result<BTreeMap<String, OutputRecord>, WriteError> {
    replace_job_products(out_dir, job, products, &[])
}

/// [`write_job_products`], also deleting the files of `<out_dir>/<job>/` named in `stale` that
/// are not among `products` (left by an earlier run of another kind into the same folder).
pub fn replace_job_products(
    out_dir: &Path,
    job: &str,
    products: &[Product],
    stale: &[&str],
) -> Result<BTreeMap<String, OutputRecord>, WriteError> {
    replace_products_in(&out_dir.join(job), products, stale)?;
    Ok(products
        .iter()
        .map(|p| {
            let record = OutputRecord {
                sha256: super::sha256_hex(&p.bytes),
                bytes: p.bytes.len() as u64,
            };
            (format!("{job}/{}", p.name), record)
        })
        .collect())
}

/// Write `products` into `dir` under their names, all or none of them, deleting the files of
/// `dir` named in `stale` that are not among `products` once every product is written.
pub fn replace_products_in(
    dir: &Path,
    products: &[Product],
    stale: &[&str],
) -> Result<(), WriteError> {
    let paths: Vec<PathBuf> = products.iter().map(|p| dir.join(&p.name)).collect();
    let remove: Vec<PathBuf> = stale
        .iter()
        .filter(|name| !products.iter().any(|p| p.name == **name))
        .map(|name| dir.join(name))
        .collect();
    let files: Vec<(&Path, &[u8])> = paths
        .iter()
        .zip(products)
        .map(|(path, p)| (path.as_path(), p.bytes.as_slice()))
        .collect();
    write_all_atomic(&files, &remove)
}

/// Delete the files of `dir` named in `names` (missing ones are fine), then `dir` itself if
/// that left it empty.
pub fn remove_products(dir: &Path, names: &[&str]) -> Result<(), WriteError> {
    for name in names {
        let path = dir.join(name);
        match std::fs::remove_file(&path) {
            Err(source) if source.kind() != std::io::ErrorKind::NotFound => {
                return Err(WriteError { path, source });
            }
            _ => {}
        }
    }
    // Fails, as it should, when the folder still holds other files (or does not exist).
    let _ = std::fs::remove_dir(dir);
    Ok(())
}

/// Write `products` to the given paths (the single commands' `-o FILE` / `--out DIR`), all or
/// none of them.
pub fn write_products_to<'a>(
    products: impl IntoIterator<Item = (&'a Path, &'a Product)>,
) -> Result<(), WriteError> {
    let files: Vec<(&Path, &[u8])> = products
        .into_iter()
        .map(|(path, p)| (path, p.bytes.as_slice()))
        .collect();
    write_all_atomic(&files, &[])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_changes_no_file_of_the_job() {
        let dir = tempfile::tempdir().unwrap();
        let job = dir.path().join("job");
        std::fs::create_dir(&job).unwrap();
        std::fs::write(job.join("a.txt"), "old").unwrap();
        // A file where the second product needs a folder: that product cannot be written.
        std::fs::write(job.join("sub"), "in the way").unwrap();
        let products = [
            Product::new("a.txt", b"new".to_vec()),
            Product::new("sub/b.txt", b"b".to_vec()),
        ];
        let e = write_job_products(dir.path(), "job", &products).unwrap_err();
        assert!(e.path.ends_with("sub/b.txt"), "{e}");
        assert_eq!(std::fs::read_to_string(job.join("a.txt")).unwrap(), "old");
        let mut left: Vec<String> = std::fs::read_dir(&job)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["a.txt", "sub"], "no temporary file is left");
    }
}
