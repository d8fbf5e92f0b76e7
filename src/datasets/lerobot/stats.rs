//! Feature statistics as LeRobot stores them (meta/stats.json and the `stats/<feature>/<stat>`
//! columns of meta/episodes): [`Stats`] of numeric rows and [`ImageStats`] of RGB frames.
use std::sync::Arc;

use arrow_array::builder::ListBuilder;
use arrow_array::ArrayRef;
use serde_json::{json, Map, Value};

/// The quantiles LeRobot stores with every feature's statistics (its `q01` ... `q99`).
pub const QUANTILES: [(&str, f64); 5] = [
    ("q01", 0.01),
    ("q10", 0.10),
    ("q50", 0.50),
    ("q90", 0.90),
    ("q99", 0.99),
];

/// Statistics of one feature over a set of rows: `min`, `max`, `mean`, `std` (population),
/// the [`QUANTILES`] (linear interpolation between order statistics, numpy's default) per
/// component, and `count` (rows, or frames for images).
#[derive(Debug, Clone)]
pub(super) struct Stats {
    /// Image statistics: per channel, stored with shape (3, 1, 1) as LeRobot's.
    image: bool,
    /// (name, per-component values), in LeRobot's order.
    entries: Vec<(&'static str, Vec<f64>)>,
    count: u64,
}

/// The `q`-quantile of sorted values (numpy's linear method).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len().max(1) - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = (lo + 1).min(sorted.len().saturating_sub(1));
    let f = pos - lo as f64;
    sorted.get(lo).map_or(0.0, |a| a + (sorted[hi] - a) * f)
}

impl Stats {
    /// Statistics of the rows of a (rows × dim) matrix.
    pub(super) fn of_rows(values: &[f64], dim: usize) -> Stats {
        let dim = dim.max(1);
        let rows = values.len() / dim;
        let n = rows.max(1) as f64;
        let mut names: Vec<(&'static str, Vec<f64>)> = ["min", "max", "mean", "std"]
            .iter()
            .chain(QUANTILES.iter().map(|(q, _)| q))
            .map(|k| (*k, Vec::with_capacity(dim)))
            .collect();
        let mut column = Vec::with_capacity(rows);
        for j in 0..dim {
            column.clear();
            column.extend(values.iter().skip(j).step_by(dim).copied());
            let mean = column.iter().sum::<f64>() / n;
            let var = column.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
            column.sort_by(f64::total_cmp);
            let mut v = vec![
                column.first().copied().unwrap_or(0.0),
                column.last().copied().unwrap_or(0.0),
                mean,
                var.sqrt(),
            ];
            v.extend(QUANTILES.iter().map(|(_, q)| quantile(&column, *q)));
            for (e, x) in names.iter_mut().zip(v) {
                e.1.push(x);
            }
        }
        Stats {
            image: false,
            entries: names,
            count: rows as u64,
        }
    }

    /// `{"min": [...], ..., "count": [n]}` (images: every value as `[[x]]`).
    pub(super) fn to_json(&self) -> Value {
        let mut m = Map::new();
        for (k, v) in &self.entries {
            let v = if self.image {
                json!(v.iter().map(|x| json!([[x]])).collect::<Vec<_>>())
            } else {
                json!(v)
            };
            m.insert((*k).into(), v);
            if *k == "std" {
                m.insert("count".into(), json!([self.count]));
            }
        }
        Value::Object(m)
    }
}

/// Running per-channel statistics of RGB frames (values scaled to 0..1, as LeRobot's): a
/// histogram of the 256 levels per channel, from which every statistic is exact.
#[derive(Clone)]
pub(super) struct ImageStats {
    hist: Vec<[u64; 256]>,
    pixels: u64,
    frames: u64,
}

impl Default for ImageStats {
    fn default() -> Self {
        ImageStats {
            hist: vec![[0; 256]; 3],
            pixels: 0,
            frames: 0,
        }
    }
}

impl ImageStats {
    pub(super) fn add(&mut self, rgb: &[u8]) {
        for px in rgb.chunks_exact(3) {
            for (c, &p) in px.iter().enumerate() {
                self.hist[c][p as usize] += 1;
            }
        }
        self.pixels += (rgb.len() / 3) as u64;
        self.frames += 1;
    }

    pub(super) fn merge(&mut self, o: &ImageStats) {
        for (h, oh) in self.hist.iter_mut().zip(&o.hist) {
            for (a, b) in h.iter_mut().zip(oh) {
                *a += b;
            }
        }
        self.pixels += o.pixels;
        self.frames += o.frames;
    }

    /// The value of rank `k` (0-based) of channel `c`.
    fn ranked(&self, c: usize, k: u64) -> f64 {
        let mut seen = 0;
        for (level, &n) in self.hist[c].iter().enumerate() {
            seen += n;
            if seen > k {
                return level as f64 / 255.0;
            }
        }
        1.0
    }

    pub(super) fn stats(&self) -> Stats {
        let n = self.pixels.max(1) as f64;
        let moment = |c: usize, f: &dyn Fn(f64) -> f64| -> f64 {
            self.hist[c]
                .iter()
                .enumerate()
                .map(|(level, &k)| k as f64 * f(level as f64 / 255.0))
                .sum::<f64>()
                / n
        };
        let mean: Vec<f64> = (0..3).map(|c| moment(c, &|v| v)).collect();
        let std: Vec<f64> = (0..3)
            .map(|c| moment(c, &|v| (v - mean[c]) * (v - mean[c])).sqrt())
            .collect();
        let last = self.pixels.saturating_sub(1);
        let quant = |q: f64| -> Vec<f64> {
            (0..3)
                .map(|c| {
                    let pos = q * last as f64;
                    let lo = pos.floor() as u64;
                    let a = self.ranked(c, lo);
                    a + (self.ranked(c, (lo + 1).min(last)) - a) * (pos - lo as f64)
                })
                .collect()
        };
        let mut entries = vec![
            ("min", quant(0.0)),
            ("max", quant(1.0)),
            ("mean", mean),
            ("std", std),
        ];
        entries.extend(QUANTILES.iter().map(|(k, q)| (*k, quant(*q))));
        Stats {
            image: true,
            entries,
            count: self.frames,
        }
    }
}

/// The per-episode columns of one feature's statistics, in LeRobot's order (`min`, `max`,
/// `mean`, `std`, `count`, quantiles): lists of float64 (images: 3 × `[[x]]`, shape (3, 1, 1)),
/// `count` a list of one int64.
pub(super) fn stats_columns(per_episode: &[Stats]) -> Vec<(&'static str, ArrayRef)> {
    use arrow_array::builder::{Float64Builder, Int64Builder};
    let Some(first) = per_episode.first() else {
        return Vec::new();
    };
    let mut out: Vec<(&'static str, ArrayRef)> = Vec::new();
    for (i, (name, _)) in first.entries.iter().enumerate() {
        let col: ArrayRef = if first.image {
            let mut b = ListBuilder::new(ListBuilder::new(ListBuilder::new(Float64Builder::new())));
            for st in per_episode {
                for &x in &st.entries[i].1 {
                    b.values().values().values().append_value(x);
                    b.values().values().append(true);
                    b.values().append(true);
                }
                b.append(true);
            }
            Arc::new(b.finish())
        } else {
            let mut b = ListBuilder::new(Float64Builder::new());
            for st in per_episode {
                b.values().append_slice(&st.entries[i].1);
                b.append(true);
            }
            Arc::new(b.finish())
        };
        out.push((name, col));
        if *name == "std" {
            let mut b = ListBuilder::new(Int64Builder::new());
            for st in per_episode {
                b.values().append_value(st.count as i64);
                b.append(true);
            }
            out.push(("count", Arc::new(b.finish())));
        }
    }
    out
}
