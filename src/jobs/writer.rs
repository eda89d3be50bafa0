//! Jobs — the writer. In: a job's [`Product`]s and the output folder. Out: the files
//! `<out>/<job>/<product>`, each written atomically by [`crate::output::write_atomic`] (a
//! temporary file beside it, then a rename, so a killed run never leaves a partial file under a
//! final name), and their manifest records (SHA-256 and size).

use std::collections::BTreeMap;
use std::path::Path;

use super::Product;
use super::manifest::OutputRecord;
use crate::output::{WriteError, write_atomic};

/// Write `products` into `<out_dir>/<job>/`; returns each file's record keyed by its path
/// relative to `out_dir` (`<job>/<product>`, with `/` separators).
pub fn write_job_products(
    out_dir: &Path,
    job: &str,
    products: &[Product],
) -> Result<BTreeMap<String, OutputRecord>, WriteError> {
    let mut records = BTreeMap::new();
    for product in products {
        let rel = format!("{job}/{}", product.name);
        write_atomic(&out_dir.join(job).join(&product.name), &product.bytes)?;
        records.insert(
            rel,
            OutputRecord {
                sha256: super::sha256_hex(&product.bytes),
                bytes: product.bytes.len() as u64,
            },
        );
    }
    Ok(records)
}

/// Write `products` to the given paths (the single commands' `-o FILE` / `--out DIR`).
pub fn write_products_to<'a>(
    products: impl IntoIterator<Item = (&'a Path, &'a Product)>,
) -> Result<(), WriteError> {
    for (path, product) in products {
        write_atomic(path, &product.bytes)?;
    }
    Ok(())
}
