//! The module graph runs one way: FFI → `mujoco` → `controllers` → `mjcf` → `robots` →
//! `tasks` → `env` → `record` → (`maniskill`, `solvers`) → `datasets`, with the leaves
//! `rng` (ManiSkill's RNG emulation), `models` (the embedded robot files) and `obs` (the
//! observation writer) below everything, and the crate's internal cross-layer tests
//! (`src/tests/`) above. The command line (`src/bin/mjskill/`) is a separate crate on the
//! public API.
//!
//! This test reads every `src/**/*.rs`, collects the top-level module each `crate::` path
//! names (in `use` lines, code and intra-doc links alike, `use crate::{a::X, b::Y}` groups
//! included), prints the graph and fails on any edge that points up or sideways (a
//! back-edge). Run it with `--nocapture` to see the graph.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layers, lowest first. A module may only use modules of a strictly lower layer.
const LAYERS: &[&[&str]] = &[
    &["rng", "models", "obs", "files"],
    &["mujoco"],
    // The controllers own the robot description (URDF, drives) that the MJCF writer consumes.
    &["controllers"],
    &["mjcf"],
    &["robots"],
    &["tasks"],
    &["env"],
    &["record"],
    &["maniskill", "solvers"],
    &["datasets"],
    &["tests"],
];

fn layer(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src dir") {
        let path = entry.expect("dir entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

fn ident(s: &str) -> &str {
    let end = s
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    &s[..end]
}

/// The top-level modules a source text names through `crate::` paths.
fn crate_targets(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut rest = text;
    while let Some(i) = rest.find("crate::") {
        let before = rest[..i].chars().next_back();
        let after = &rest[i + "crate::".len()..];
        rest = after;
        // `$crate::` (macros) and `mycrate::` are not paths of this crate.
        if before.is_some_and(|c| c == '$' || c.is_ascii_alphanumeric() || c == '_') {
            continue;
        }
        if let Some(group) = after.strip_prefix('{') {
            // `crate::{a::X, b::{Y, Z}, c}`: the first identifier of each depth-0 item.
            let mut depth = 0usize;
            let mut item_start = true;
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => item_start = true,
                    c if item_start && (c.is_ascii_alphabetic() || c == '_') => {
                        out.insert(ident(&group[k..]).to_string());
                        item_start = false;
                    }
                    _ => {}
                }
            }
        } else {
            let id = ident(after);
            if !id.is_empty() {
                out.insert(id.to_string());
            }
        }
    }
    out
}

#[test]
fn module_graph_has_no_back_edges() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    // module → (used module → first file that uses it)
    let mut graph: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    let mut unknown = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&src).expect("under src");
        let first = rel.components().next().expect("non-empty path");
        let module = first
            .as_os_str()
            .to_string_lossy()
            .trim_end_matches(".rs")
            .to_string();
        if module == "lib" || module == "bin" {
            continue;
        }
        if layer(&module).is_none() {
            unknown.push(format!("{} (module {module})", rel.display()));
            continue;
        }
        let text = std::fs::read_to_string(f).expect("read source");
        let uses = graph.entry(module.clone()).or_default();
        for t in crate_targets(&text) {
            if t != module {
                uses.entry(t).or_insert_with(|| rel.display().to_string());
            }
        }
    }
    assert!(
        unknown.is_empty(),
        "modules missing from LAYERS (place them in a layer): {unknown:?}"
    );

    let mut back_edges = Vec::new();
    println!("module graph (layer: module -> modules it uses):");
    for (l, mods) in LAYERS.iter().enumerate() {
        for m in *mods {
            let Some(uses) = graph.get(*m) else {
                continue;
            };
            let names: Vec<&str> = uses.keys().map(String::as_str).collect();
            println!(
                "  {l}: {m} -> {}",
                if names.is_empty() {
                    "(nothing)".to_string()
                } else {
                    names.join(", ")
                }
            );
            for (t, file) in uses {
                match layer(t) {
                    Some(tl) if tl < l => {}
                    Some(_) => back_edges.push(format!("{m} -> {t} (in src/{file})")),
                    None => back_edges.push(format!("{m} -> unknown module {t} (in src/{file})")),
                }
            }
        }
    }
    println!("back-edges: {}", back_edges.len());
    assert!(
        back_edges.is_empty(),
        "the module graph must run one way; back-edges:\n  {}",
        back_edges.join("\n  ")
    );
}

#[test]
fn crate_targets_reads_groups_and_skips_macros() {
    let t = crate_targets(
        "use crate::{env::Env, record::{A, B}, tasks};\n let x = crate::mjcf::TIMESTEP;\n $crate::rng::f();",
    );
    let v: Vec<&str> = t.iter().map(String::as_str).collect();
    assert_eq!(v, ["env", "mjcf", "record", "tasks"]);
}
