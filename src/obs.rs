//! The observation writer: observation parts are declared once, by writing them.
//!
//! Like ManiSkill's `obs.update(key=value)`, the code that produces a part of the observation
//! names it where it writes it (`out.pose("tcp_pose", p, q)`), so the layout and the values
//! cannot drift apart. A writer runs in one of two modes:
//!
//! * **layout** ([`ObsWriter::layout`]), once when an env is built: every write records
//!   `(prefix + name, range)` and the values are dropped;
//! * **values** ([`ObsWriter::values`]), every reset and step: the values go, in the same
//!   order, into the preallocated observation buffer. Names are ignored, so this mode
//!   allocates nothing and looks nothing up.
use std::ops::Range;

/// A named part of the flat observation: key (e.g. `extra/tcp_pose`) and its range.
pub type ObsPart = (String, Range<usize>);

#[derive(Debug)]
enum Sink<'a> {
    Layout(&'a mut Vec<ObsPart>),
    Values(&'a mut [f32]),
}

/// Writes observation parts in order; see the module docs.
#[derive(Debug)]
pub struct ObsWriter<'a> {
    sink: Sink<'a>,
    pos: usize,
    prefix: &'static str,
}

impl<'a> ObsWriter<'a> {
    /// A writer that records the layout into `layout` (appending) and drops the values.
    pub fn layout(layout: &'a mut Vec<ObsPart>) -> ObsWriter<'a> {
        ObsWriter {
            sink: Sink::Layout(layout),
            pos: 0,
            prefix: "",
        }
    }

    /// A writer that writes the values into `out`, from its start, in the order of the layout
    /// pass.
    ///
    /// # Panics
    /// If the parts written exceed `out` (a buffer not sized by the layout pass).
    pub fn values(out: &'a mut [f32]) -> ObsWriter<'a> {
        ObsWriter {
            sink: Sink::Values(out),
            pos: 0,
            prefix: "",
        }
    }

    /// Sets the key prefix of the following parts (e.g. `"extra/"`).
    pub fn set_prefix(&mut self, prefix: &'static str) {
        self.prefix = prefix;
    }

    /// Number of values written so far (after the layout pass: the observation length).
    pub fn len(&self) -> usize {
        self.pos
    }

    /// Writes a part whose key is the path `segments` joined by `/` after the prefix (e.g.
    /// `["arm", "target_qpos"]`), with the values as f32.
    pub fn put_path(&mut self, segments: &[&str], values: impl IntoIterator<Item = f64>) {
        let start = self.pos;
        match &mut self.sink {
            Sink::Values(out) => {
                for v in values {
                    out[self.pos] = v as f32;
                    self.pos += 1;
                }
            }
            Sink::Layout(layout) => {
                self.pos += values.into_iter().count();
                let key = format!("{}{}", self.prefix, segments.join("/"));
                layout.push((key, start..self.pos));
            }
        }
    }

    /// Writes a part named `name` (after the prefix).
    pub fn put(&mut self, name: &str, values: impl IntoIterator<Item = f64>) {
        self.put_path(&[name], values);
    }

    /// Writes one value (a flag as 0/1, a distance).
    pub fn scalar(&mut self, name: &str, x: f64) {
        self.put(name, [x]);
    }

    /// Writes a 3-vector.
    pub fn vec3(&mut self, name: &str, v: nalgebra::Vector3<f64>) {
        self.put(name, [v.x, v.y, v.z]);
    }

    /// Writes a pose as `[x, y, z, qw, qx, qy, qz]`.
    pub fn pose(&mut self, name: &str, p: nalgebra::Vector3<f64>, q: [f64; 4]) {
        self.put(name, [p.x, p.y, p.z, q[0], q[1], q[2], q[3]]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn write(w: &mut ObsWriter) {
        w.put("qpos", [1.0, 2.0]);
        w.set_prefix("extra/");
        w.scalar("flag", 1.0);
        w.pose(
            "tcp_pose",
            Vector3::new(0.1, 0.2, 0.3),
            [1.0, 0.0, 0.0, 0.0],
        );
        w.put_path(&["arm", "target_qpos"], [0.5]);
    }

    #[test]
    fn layout_and_values_come_from_the_same_writes() {
        let mut layout = Vec::new();
        let mut w = ObsWriter::layout(&mut layout);
        write(&mut w);
        let n = w.len();
        assert_eq!(n, 11);
        let keys: Vec<(&str, Range<usize>)> = layout
            .iter()
            .map(|(k, r)| (k.as_str(), r.clone()))
            .collect();
        assert_eq!(
            keys,
            [
                ("qpos", 0..2),
                ("extra/flag", 2..3),
                ("extra/tcp_pose", 3..10),
                ("extra/arm/target_qpos", 10..11)
            ]
        );
        let mut buf = vec![0.0f32; n];
        let mut w = ObsWriter::values(&mut buf);
        write(&mut w);
        assert_eq!(w.len(), n);
        assert_eq!(buf, [1.0, 2.0, 1.0, 0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0, 0.5]);
    }

    #[test]
    #[should_panic]
    fn values_beyond_the_buffer_panic() {
        let mut buf = [0.0f32; 1];
        ObsWriter::values(&mut buf).put("x", [1.0, 2.0]);
    }
}
