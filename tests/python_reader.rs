//! Recordings read with Python's `mcap` package, as a Python user would: the streaming reader
//! documented in docs/recording.md (run verbatim from the document) recovers every finished
//! episode of a killed recording, and every message of complete and killed recordings
//! validates against its channel's JSON schema (Python's `jsonschema`).
//!
//! The Python packages live in the venv `.ci/setup` creates (`.ci/venv`). Without it the tests
//! print a note and pass, unless `MJSKILL_REQUIRE_PYTHON` is set (`.ci/run` sets it).

use std::path::{Path, PathBuf};
use std::process::Command;

use mjskill::record::{self, Recorder};
use mjskill::{make, EnvConfig};

mod common;

fn python() -> Option<PathBuf> {
    common::venv_python("Python reader test")
}

/// The Python block of docs/recording.md's "Reading it elsewhere" section.
fn documented_example() -> String {
    let doc =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/recording.md"))
            .unwrap();
    let section = &doc[doc.find("## Reading it elsewhere").expect("section")..];
    let start = section.find("```python\n").expect("python block") + "```python\n".len();
    let end = start + section[start..].find("```").expect("end of block");
    section[start..end].to_string()
}

/// Records `finished` episodes of `steps` steps (plus, when `killed`, an unfinished one of 2
/// steps after which the recorder is abandoned as a kill would leave it), with video frames
/// when `video`.
fn record_file(path: &Path, finished: usize, steps: usize, killed: bool, video: bool) {
    let mut env = make("PickCube-v1", EnvConfig::default()).unwrap();
    let mut rec = Recorder::create(path, &env).unwrap();
    let (w, h) = env.render_size();
    if video {
        rec.enable_video("render_camera").unwrap();
    }
    let dim = env.action_space().shape[0];
    let episodes = finished + usize::from(killed);
    for ep in 0..episodes {
        rec.reset(&mut env, Some(ep as u64)).unwrap();
        if video {
            let rgb = env.render().unwrap().to_vec();
            rec.record_frame(&rgb, w, h).unwrap();
        }
        let n = if ep < finished { steps } else { 2 };
        for t in 0..n {
            let a: Vec<f32> = (0..dim).map(|i| ((i + t) as f32 * 0.3).sin()).collect();
            rec.step(&mut env, &a).unwrap();
            if video {
                let rgb = env.render().unwrap().to_vec();
                rec.record_frame(&rgb, w, h).unwrap();
            }
        }
        if ep < finished {
            rec.end_episode(env.info().success()).unwrap();
        }
    }
    if killed {
        rec.abandon().unwrap();
    } else {
        rec.finish().unwrap();
    }
}

fn run(py: &Path, script: &Path, file: &Path) -> (String, String) {
    let o = Command::new(py).arg(script).arg(file).output().unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout).to_string(),
        String::from_utf8_lossy(&o.stderr).to_string(),
    );
    assert!(o.status.success(), "{}: {err}", script.display());
    (out, err)
}

#[test]
fn the_documented_python_reader_recovers_every_finished_episode() {
    let Some(py) = python() else { return };
    let script = common::scratch("example.py");
    std::fs::write(&script, documented_example()).unwrap();
    for (name, killed) in [("complete.mcap", false), ("killed.mcap", true)] {
        let path = common::scratch(name);
        record_file(&path, 3, 4, killed, false);
        let rec = record::read(&path).unwrap();
        assert_eq!(rec.complete, !killed);
        let (out, err) = run(&py, &script, &path);
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(
            lines.len(),
            3,
            "{name}: one line per finished episode: {out}"
        );
        for (line, ep) in lines.iter().zip(rec.finished()) {
            let f: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(f[0], ep.index.to_string(), "{line}");
            assert_eq!(f[1], "4", "{line}");
            let ret: f64 = f[2].parse().unwrap();
            assert_eq!(ret, ep.ret, "{name}: Python reads the same return: {line}");
            assert_eq!(f[3], if ep.success { "True" } else { "False" });
        }
        assert_eq!(
            err.contains("cut short"),
            killed,
            "{name}: only the killed file is cut short: {err}"
        );
    }
}

#[test]
fn every_message_validates_against_its_schema() {
    let Some(py) = python() else { return };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/validate_schemas.py");
    let video = cfg!(feature = "video")
        && make("PickCube-v1", EnvConfig::default())
            .unwrap()
            .render()
            .is_ok();
    if !video {
        eprintln!("note: no EGL: the foxglove.CompressedVideo channel is not validated");
    }
    for (name, killed) in [("schemas.mcap", false), ("schemas-killed.mcap", true)] {
        let path = common::scratch(name);
        record_file(&path, 2, 3, killed, video);
        let (out, _) = run(&py, &script, &path);
        let counts: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
        assert_eq!(counts["/step"], 6, "{name}: {counts}");
        assert_eq!(counts["/episode"], 2, "{name}: {counts}");
        assert_eq!(counts["/episode_end"], 2, "{name}: {counts}");
        assert_eq!(counts["/scene"], 2, "{name}: {counts}");
        assert_eq!(counts["/tf"], 8, "{name}: {counts}");
        if video {
            assert_eq!(counts["/render_camera/video"], 8, "{name}: {counts}");
        }
    }
}
