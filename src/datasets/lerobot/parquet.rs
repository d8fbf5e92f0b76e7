//! Arrow columns and parquet files of a LeRobot export, split over `chunk-CCC/file-FFF`
//! files as LeRobot's writer splits them.
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::{ArrayRef, FixedSizeListArray, Float32Array, RecordBatch};
use arrow_schema::{DataType, Field};

use super::{chunk_file, next_file, MB};
use crate::datasets::DatasetError;

/// Feature names: `prefix` alone, or `prefix_0` ... `prefix_{n-1}`.
pub(super) fn names(prefix: &str, n: usize) -> Vec<String> {
    if n == 1 {
        vec![prefix.to_string()]
    } else {
        (0..n).map(|i| format!("{prefix}_{i}")).collect()
    }
}

/// `values` as a fixed-size list column of `dim` float32 per row.
pub(super) fn fixed_list(
    values: Vec<f32>,
    dim: usize,
) -> Result<ArrayRef, arrow_schema::ArrowError> {
    Ok(Arc::new(FixedSizeListArray::try_new(
        Arc::new(Field::new_list_field(DataType::Float32, false)),
        dim as i32,
        Arc::new(Float32Array::from(values)),
        None,
    )?))
}

/// Writes `batch` as one parquet file `out` (`final_path` in errors: where it ends up).
pub(super) fn write_parquet(
    out: &Path,
    final_path: &Path,
    batch: &RecordBatch,
) -> Result<(), DatasetError> {
    use parquet::arrow::ArrowWriter;
    use parquet::basic::Compression;
    use parquet::file::properties::WriterProperties;
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(DatasetError::io(final_path))?;
    }
    let file = std::fs::File::create(out).map_err(DatasetError::io(final_path))?;
    let props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .build();
    let perr = |source| DatasetError::Parquet {
        path: final_path.to_path_buf(),
        source,
    };
    let mut w = ArrowWriter::try_new(file, batch.schema(), Some(props)).map_err(perr)?;
    w.write(batch).map_err(perr)?;
    w.close().map_err(perr)?;
    Ok(())
}

/// Writes one parquet file per (chunk, file) under `tmp/<prefix>/`: piece `k` (one episode's
/// rows, or one episode's row of meta/episodes) of `rows_of(k)` rows is built by
/// `make(k, (chunk, file))` and appended to the current file, unless that file already holds
/// rows and its size plus the piece's expected size (the file's average bytes per row times
/// the piece's rows, LeRobot's rule) reaches `limit_mb`: then the next file is opened.
/// `flush_each`: every piece is its own row group (LeRobot's data files: one table per
/// episode) and the file's size is the bytes written; otherwise the rows stay in one row
/// group and the size is the writer's estimate of the buffered rows. Returns every piece's
/// (chunk, file).
#[allow(clippy::too_many_arguments)]
pub(super) fn write_split_parquet(
    tmp: &Path,
    dir: &Path,
    prefix: &str,
    pieces: usize,
    rows_of: impl Fn(usize) -> usize,
    make: impl Fn(usize, (usize, usize)) -> Result<RecordBatch, DatasetError>,
    limits: (f64, usize),
    flush_each: bool,
) -> Result<Vec<(usize, usize)>, DatasetError> {
    use parquet::arrow::ArrowWriter;
    use parquet::basic::Compression;
    use parquet::file::properties::WriterProperties;
    let (limit_mb, chunks_size) = limits;
    let mut at = (0, 0);
    let mut current: Option<(ArrowWriter<std::fs::File>, PathBuf)> = None;
    let mut rows_in_file = 0usize;
    let mut out = Vec::with_capacity(pieces);
    let close = |w: ArrowWriter<std::fs::File>, path: &Path| {
        w.close().map_err(|source| DatasetError::Parquet {
            path: path.to_path_buf(),
            source,
        })
    };
    for k in 0..pieces {
        let n = rows_of(k);
        let full = current.as_ref().is_some_and(|(w, _)| {
            let size = (w.bytes_written() + w.in_progress_size()) as f64;
            let per_row = size / rows_in_file.max(1) as f64;
            rows_in_file > 0 && size + per_row * n as f64 >= limit_mb * MB
        });
        if full {
            let (w, path) = current.take().expect("checked above");
            close(w, &path)?;
            at = next_file(at, chunks_size);
            rows_in_file = 0;
        }
        let batch = make(k, at)?;
        if current.is_none() {
            let rel = chunk_file(prefix, at, "parquet");
            let (out_path, final_path) = (tmp.join(&rel), dir.join(&rel));
            if let Some(d) = out_path.parent() {
                std::fs::create_dir_all(d).map_err(DatasetError::io(&final_path))?;
            }
            let file = std::fs::File::create(&out_path).map_err(DatasetError::io(&final_path))?;
            let props = WriterProperties::builder()
                .set_compression(Compression::SNAPPY)
                .build();
            let w = ArrowWriter::try_new(file, batch.schema(), Some(props)).map_err(|source| {
                DatasetError::Parquet {
                    path: final_path.clone(),
                    source,
                }
            })?;
            current = Some((w, final_path));
        }
        let (w, path) = current.as_mut().expect("opened above");
        let perr = |source| DatasetError::Parquet {
            path: path.clone(),
            source,
        };
        w.write(&batch).map_err(perr)?;
        if flush_each {
            w.flush().map_err(|source| DatasetError::Parquet {
                path: path.clone(),
                source,
            })?;
        }
        rows_in_file += n;
        out.push(at);
    }
    if let Some((w, path)) = current {
        close(w, &path)?;
    }
    Ok(out)
}
