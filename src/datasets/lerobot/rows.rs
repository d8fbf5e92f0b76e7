//! The data rows of a LeRobot export (one per step), their feature metadata, their Arrow
//! columns and the values their statistics are computed from.
use std::sync::Arc;

use arrow_array::{ArrayRef, BooleanArray, Float32Array, Int64Array, RecordBatch};
use arrow_schema::{ArrowError, DataType, Field, Schema};
use serde_json::{json, Map, Value};

use super::parquet::fixed_list;
use super::FPS;
use crate::record::EpisodeRec;

/// Every step of the exported episodes as a row, column by column.
pub(super) struct Rows {
    obs_dim: usize,
    act_dim: usize,
    state: Vec<f32>,
    action: Vec<f32>,
    reward: Vec<f32>,
    done: Vec<bool>,
    success: Vec<bool>,
    timestamp: Vec<f32>,
    frame_index: Vec<i64>,
    episode_index: Vec<i64>,
    index: Vec<i64>,
    task_index: Vec<i64>,
    /// Each episode's rows (from, to).
    pub(super) episodes: Vec<(usize, usize)>,
}

impl Rows {
    /// The rows of `episodes`: row t of an episode holds the observation before action t.
    pub(super) fn of(episodes: &[&EpisodeRec], obs_dim: usize, act_dim: usize) -> Rows {
        let mut r = Rows {
            obs_dim,
            act_dim,
            state: Vec::new(),
            action: Vec::new(),
            reward: Vec::new(),
            done: Vec::new(),
            success: Vec::new(),
            timestamp: Vec::new(),
            frame_index: Vec::new(),
            episode_index: Vec::new(),
            index: Vec::new(),
            task_index: Vec::new(),
            episodes: Vec::new(),
        };
        for (k, ep) in episodes.iter().enumerate() {
            let from = r.index.len();
            let mut obs = &ep.initial_obs;
            for (t, s) in ep.steps.iter().enumerate() {
                r.state.extend_from_slice(obs);
                r.action.extend_from_slice(&s.action);
                r.reward.push(s.reward);
                r.done.push(t + 1 == ep.steps.len());
                r.success.push(
                    s.info
                        .iter()
                        .find(|(k, _)| k == "success")
                        .is_some_and(|(_, v)| *v != 0.0),
                );
                r.timestamp.push(t as f32 / FPS as f32);
                r.frame_index.push(t as i64);
                r.episode_index.push(k as i64);
                r.index.push(r.index.len() as i64);
                obs = &s.obs;
            }
            r.episodes.push((from, r.index.len()));
        }
        r.task_index = vec![0i64; r.index.len()];
        r
    }

    /// Number of rows.
    pub(super) fn len(&self) -> usize {
        self.index.len()
    }

    /// The integer columns, by name.
    fn int_columns(&self) -> [(&'static str, &Vec<i64>); 4] {
        [
            ("frame_index", &self.frame_index),
            ("episode_index", &self.episode_index),
            ("index", &self.index),
            ("task_index", &self.task_index),
        ]
    }

    /// info.json's `features` of the row columns, with the observation's and the action's
    /// component names.
    pub(super) fn features(
        &self,
        obs_names: Vec<String>,
        act_names: Vec<String>,
    ) -> Map<String, Value> {
        let scalar = |dtype: &str| json!({"dtype": dtype, "shape": [1], "names": null});
        let mut features = Map::new();
        if self.obs_dim > 0 {
            features.insert(
                "observation.state".into(),
                json!({"dtype": "float32", "shape": [self.obs_dim], "names": obs_names}),
            );
        }
        features.insert(
            "action".into(),
            json!({"dtype": "float32", "shape": [self.act_dim], "names": act_names}),
        );
        features.insert("next.reward".into(), scalar("float32"));
        features.insert("next.done".into(), scalar("bool"));
        features.insert("next.success".into(), scalar("bool"));
        for (name, _) in self.int_columns() {
            features.insert(name.into(), scalar("int64"));
        }
        features.insert("timestamp".into(), scalar("float32"));
        features
    }

    /// The rows as one Arrow batch (the data files' columns, in LeRobot's order).
    pub(super) fn batch(&self) -> Result<RecordBatch, ArrowError> {
        let mut fields = Vec::new();
        let mut cols: Vec<ArrayRef> = Vec::new();
        let list_field = |name: &str, dim: usize| {
            Field::new(
                name,
                DataType::FixedSizeList(
                    Arc::new(Field::new_list_field(DataType::Float32, false)),
                    dim as i32,
                ),
                false,
            )
        };
        if self.obs_dim > 0 {
            fields.push(list_field("observation.state", self.obs_dim));
            cols.push(fixed_list(self.state.clone(), self.obs_dim)?);
        }
        fields.push(list_field("action", self.act_dim));
        cols.push(fixed_list(self.action.clone(), self.act_dim)?);
        fields.push(Field::new("next.reward", DataType::Float32, false));
        cols.push(Arc::new(Float32Array::from(self.reward.clone())));
        fields.push(Field::new("next.done", DataType::Boolean, false));
        cols.push(Arc::new(BooleanArray::from(self.done.clone())));
        fields.push(Field::new("next.success", DataType::Boolean, false));
        cols.push(Arc::new(BooleanArray::from(self.success.clone())));
        fields.push(Field::new("timestamp", DataType::Float32, false));
        cols.push(Arc::new(Float32Array::from(self.timestamp.clone())));
        for (name, v) in self.int_columns() {
            fields.push(Field::new(name, DataType::Int64, false));
            cols.push(Arc::new(Int64Array::from(v.clone())));
        }
        RecordBatch::try_new(Arc::new(Schema::new(fields)), cols)
    }

    /// Every column as f64 values with its width: (name, values, dim), what the statistics
    /// of meta/stats.json and meta/episodes are computed from.
    pub(super) fn stat_columns(&self) -> Vec<(&'static str, Vec<f64>, usize)> {
        let widen = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
        let bools = |v: &[bool]| v.iter().map(|&x| x as u8 as f64).collect::<Vec<_>>();
        let ints = |v: &[i64]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
        let mut columns: Vec<(&str, Vec<f64>, usize)> = Vec::new();
        if self.obs_dim > 0 {
            columns.push(("observation.state", widen(&self.state), self.obs_dim));
        }
        columns.push(("action", widen(&self.action), self.act_dim));
        columns.push(("next.reward", widen(&self.reward), 1));
        columns.push(("next.done", bools(&self.done), 1));
        columns.push(("next.success", bools(&self.success), 1));
        columns.push(("timestamp", widen(&self.timestamp), 1));
        for (name, v) in self.int_columns() {
            columns.push((name, ints(v), 1));
        }
        columns
    }
}
