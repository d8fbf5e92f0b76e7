//! meta/episodes (one row per episode: length, task, where its data and video went, its
//! statistics) and meta/tasks.parquet of a LeRobot export.
use std::path::Path;
use std::sync::Arc;

use arrow_array::builder::{ListBuilder, StringBuilder};
use arrow_array::{ArrayRef, Int64Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use serde_json::json;

use super::parquet::{write_parquet, write_split_parquet};
use super::stats::{stats_columns, Stats};
use crate::datasets::DatasetError;

/// What meta/episodes says about the episodes besides their statistics.
pub(super) struct EpisodesMeta<'a> {
    /// The task of every episode.
    pub(super) task: &'a str,
    /// Each episode's rows (from, to) in the dataset.
    pub(super) rows: &'a [(usize, usize)],
    /// Each episode's data file (chunk, file).
    pub(super) data_at: &'a [(usize, usize)],
    /// The `videos/<key>/...` columns.
    pub(super) video_cols: Vec<(Field, ArrayRef)>,
    /// Per feature: each episode's statistics.
    pub(super) stats: &'a [(String, Vec<Stats>)],
}

/// Writes meta/episodes under `tmp` (`dir` in errors), split as LeRobot splits it
/// (`limits`: megabytes per file, files per chunk).
pub(super) fn write_episodes(
    tmp: &Path,
    dir: &Path,
    meta: EpisodesMeta<'_>,
    limits: (f64, usize),
) -> Result<(), DatasetError> {
    let aerr = |source| DatasetError::Arrow {
        path: dir.to_path_buf(),
        source,
    };
    let n = meta.rows.len();
    let mut tasks_col = ListBuilder::new(StringBuilder::new());
    for _ in 0..n {
        tasks_col.values().append_value(meta.task);
        tasks_col.append(true);
    }
    let mut ep_fields = vec![
        Field::new("episode_index", DataType::Int64, false),
        Field::new(
            "tasks",
            DataType::List(Arc::new(Field::new_list_field(DataType::Utf8, true))),
            true,
        ),
        Field::new("length", DataType::Int64, false),
        Field::new("data/chunk_index", DataType::Int64, false),
        Field::new("data/file_index", DataType::Int64, false),
        Field::new("dataset_from_index", DataType::Int64, false),
        Field::new("dataset_to_index", DataType::Int64, false),
    ];
    let ints = |f: &dyn Fn(usize) -> usize| -> ArrayRef {
        Arc::new(Int64Array::from(
            (0..n).map(|k| f(k) as i64).collect::<Vec<_>>(),
        ))
    };
    let mut ep_cols: Vec<ArrayRef> = vec![
        ints(&|k| k),
        Arc::new(tasks_col.finish()),
        ints(&|k| meta.rows[k].1 - meta.rows[k].0),
        ints(&|k| meta.data_at[k].0),
        ints(&|k| meta.data_at[k].1),
        ints(&|k| meta.rows[k].0),
        ints(&|k| meta.rows[k].1),
    ];
    for (f, c) in meta.video_cols {
        ep_fields.push(f);
        ep_cols.push(c);
    }
    for (key, per) in meta.stats {
        for (name, col) in stats_columns(per) {
            ep_fields.push(Field::new(
                format!("stats/{key}/{name}"),
                col.data_type().clone(),
                true,
            ));
            ep_cols.push(col);
        }
    }
    for name in ["meta/episodes/chunk_index", "meta/episodes/file_index"] {
        ep_fields.push(Field::new(name, DataType::Int64, false));
    }
    let ep_schema = Arc::new(Schema::new(ep_fields));
    // Every episode's row, with the meta/episodes file it goes into.
    let ep_row = |k: usize, at: (usize, usize)| -> Result<RecordBatch, DatasetError> {
        let mut cols: Vec<ArrayRef> = ep_cols.iter().map(|c| c.slice(k, 1)).collect();
        cols.push(Arc::new(Int64Array::from(vec![at.0 as i64])));
        cols.push(Arc::new(Int64Array::from(vec![at.1 as i64])));
        RecordBatch::try_new(ep_schema.clone(), cols).map_err(aerr)
    };
    write_split_parquet(tmp, dir, "meta/episodes", n, |_| 1, ep_row, limits, false)?;
    Ok(())
}

/// Writes meta/tasks.parquet: the one task, its string the pandas index (LeRobot reads it
/// with pandas).
pub(super) fn write_tasks(tmp: &Path, dir: &Path, task: &str) -> Result<(), DatasetError> {
    let pandas = json!({
        "index_columns": ["task"],
        "column_indexes": [],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": null}
        ],
        "creator": {"library": "mjskill", "version": env!("CARGO_PKG_VERSION")},
        "pandas_version": "2.2.0"
    });
    let tasks_schema = Schema::new(vec![
        Field::new("task_index", DataType::Int64, false),
        Field::new("task", DataType::Utf8, false),
    ])
    .with_metadata(std::collections::HashMap::from([(
        "pandas".to_string(),
        pandas.to_string(),
    )]));
    let tasks = RecordBatch::try_new(
        Arc::new(tasks_schema),
        vec![
            Arc::new(Int64Array::from(vec![0i64])),
            Arc::new(arrow_array::StringArray::from(vec![task.to_string()])),
        ],
    )
    .map_err(|source| DatasetError::Arrow {
        path: dir.to_path_buf(),
        source,
    })?;
    write_parquet(
        &tmp.join("meta/tasks.parquet"),
        &dir.join("meta/tasks.parquet"),
        &tasks,
    )
}
