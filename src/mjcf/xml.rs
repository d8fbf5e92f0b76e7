//! A minimal XML element tree for writing MJCF: elements are built in any order, then
//! serialised with escaped attribute values and stable attribute order.
use std::fmt::Write;

/// One XML element with attributes (in insertion order) and child elements.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Element {
    /// Tag name.
    pub name: String,
    /// Attributes in insertion order.
    pub attrs: Vec<(String, String)>,
    /// Child elements.
    pub children: Vec<Element>,
    /// Optional comment written before the element.
    pub comment: Option<String>,
}

/// Formats a float the shortest way that round-trips exactly (so the MJCF carries the exact
/// f64 values of the URDF figures).
pub fn num(x: f64) -> String {
    if x == 0.0 {
        "0".to_string()
    } else {
        format!("{x}")
    }
}

/// Formats a list of floats separated by spaces.
pub fn nums(xs: &[f64]) -> String {
    xs.iter().map(|x| num(*x)).collect::<Vec<_>>().join(" ")
}

impl Element {
    /// A new element with this tag.
    pub fn new(name: &str) -> Self {
        Element {
            name: name.to_string(),
            ..Default::default()
        }
    }
    /// Builder: adds an attribute.
    pub fn attr(mut self, k: &str, v: impl ToString) -> Self {
        self.set(k, v);
        self
    }
    /// Builder: adds a float-list attribute.
    pub fn attr_nums(mut self, k: &str, v: &[f64]) -> Self {
        self.set(k, nums(v));
        self
    }
    /// Builder: adds a child.
    pub fn child(mut self, c: Element) -> Self {
        self.children.push(c);
        self
    }
    /// Sets (or replaces) an attribute.
    pub fn set(&mut self, k: &str, v: impl ToString) {
        let v = v.to_string();
        if let Some(slot) = self.attrs.iter_mut().find(|(kk, _)| kk == k) {
            slot.1 = v;
        } else {
            self.attrs.push((k.to_string(), v));
        }
    }
    /// Appends a child and returns a mutable reference to it.
    pub fn push(&mut self, c: Element) -> &mut Element {
        self.children.push(c);
        self.children.last_mut().expect("just pushed")
    }
    /// The first direct child with this tag, created (appended) if missing.
    pub fn section(&mut self, name: &str) -> &mut Element {
        match self.children.iter().position(|c| c.name == name) {
            Some(i) => &mut self.children[i],
            None => self.push(Element::new(name)),
        }
    }
    /// Serialises the tree with two-space indentation.
    pub fn to_xml(&self) -> String {
        let mut s = String::new();
        self.write(&mut s, 0);
        s
    }

    fn write(&self, s: &mut String, depth: usize) {
        let pad = "  ".repeat(depth);
        if let Some(c) = &self.comment {
            let _ = writeln!(s, "{pad}<!-- {} -->", c.replace("--", "- -"));
        }
        let _ = write!(s, "{pad}<{}", self.name);
        for (k, v) in &self.attrs {
            let _ = write!(s, " {k}=\"{}\"", escape(v));
        }
        if self.children.is_empty() {
            s.push_str("/>\n");
        } else {
            s.push_str(">\n");
            for c in &self.children {
                c.write(s, depth + 1);
            }
            let _ = writeln!(s, "{pad}</{}>", self.name);
        }
    }
}

fn escape(v: &str) -> String {
    v.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serialises_nested_and_escapes() {
        let mut root = Element::new("mujoco").attr("model", "a<b");
        root.section("worldbody")
            .push(Element::new("geom").attr_nums("size", &[0.5, 1.0, 1e-6]));
        root.section("worldbody").push(Element::new("body"));
        let x = root.to_xml();
        assert!(x.contains("model=\"a&lt;b\""), "{x}");
        assert!(x.contains("size=\"0.5 1 0.000001\""), "{x}");
        assert_eq!(x.matches("<worldbody>").count(), 1);
        let parsed = roxmltree::Document::parse(&x).unwrap();
        assert_eq!(
            parsed
                .root_element()
                .children()
                .filter(|n| n.is_element())
                .count(),
            1
        );
    }

    #[test]
    fn floats_roundtrip() {
        for x in [0.1, 1.0 / 3.0, -2.8973, 1e-6, 3.5762787e-07 + 0.91964257] {
            assert_eq!(num(x).parse::<f64>().unwrap(), x);
        }
    }
}
