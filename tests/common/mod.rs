//! Helpers shared by the integration tests: `export-mjcf` runs (checked by mjskill's MuJoCo
//! and by Debian's `mujoco-compile`), the task tests' observation and state helpers, and
//! command runs bounded in time (`run_within`), and the scratch directory for test files
//! (`scratch`, `scratch_dir`).
#![allow(dead_code)]
pub mod rollout;
pub mod task;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use mjskill::mujoco::Model;

/// The Python of `.ci/venv` (made by `bash .ci/setup`), or `None` with a note that `test` is
/// skipped; with `MJSKILL_REQUIRE_PYTHON` set, a missing venv fails the test instead.
pub fn venv_python(test: &str) -> Option<std::path::PathBuf> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/venv/bin/python");
    if p.exists() {
        return Some(p);
    }
    assert!(
        std::env::var_os("MJSKILL_REQUIRE_PYTHON").is_none(),
        "{} is missing: run `bash .ci/setup`",
        p.display()
    );
    eprintln!(
        "note: {test} skipped: {} is missing (run `bash .ci/setup` to create it)",
        p.display()
    );
    None
}

/// Prefix of the test processes' scratch directories under `CARGO_TARGET_TMPDIR`.
const SCRATCH_PREFIX: &str = "mjskill-tests-";

/// This test process's scratch directory, `target/tmp/mjskill-tests-PID` (Cargo's
/// `CARGO_TARGET_TMPDIR`): test files stay inside the target directory, never in the system's
/// temp directory. The first call removes the directories of test processes that have exited,
/// so only the last test binary's files stay behind (for a look after a failure).
fn scratch_root() -> &'static Path {
    static ROOT: OnceLock<PathBuf> = OnceLock::new();
    ROOT.get_or_init(|| {
        let base = Path::new(env!("CARGO_TARGET_TMPDIR"));
        for entry in std::fs::read_dir(base).into_iter().flatten().flatten() {
            let name = entry.file_name();
            let pid = name.to_str().and_then(|n| n.strip_prefix(SCRATCH_PREFIX));
            if let Some(pid) = pid.and_then(|p| p.parse::<u32>().ok()) {
                if !Path::new(&format!("/proc/{pid}")).exists() {
                    let _ = std::fs::remove_dir_all(entry.path());
                }
            }
        }
        let root = base.join(format!("{SCRATCH_PREFIX}{}", std::process::id()));
        std::fs::create_dir_all(&root).unwrap();
        root
    })
}

/// The path of a file named `name` in this test process's scratch directory (`scratch_root`).
/// Names are unique within a test binary: its tests run at once and share the directory.
pub fn scratch(name: &str) -> PathBuf {
    scratch_root().join(name)
}

/// A directory named `name` in this test process's scratch directory, created if missing.
pub fn scratch_dir(name: &str) -> PathBuf {
    let d = scratch(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The error line of an mjskill run that must fail with the error exit code (2), not a crash:
/// stderr starts with `error: ` and holds no panic message.
pub fn fails(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(
        o.status.code(),
        Some(2),
        "expected the error exit code: {err}"
    );
    assert!(err.starts_with("error: "), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// Runs `cmd`, failing the test if it takes longer than `secs` seconds (a hang).
pub fn run_within(mut cmd: Command, secs: u64) -> Output {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed() > Duration::from_secs(secs) {
            child.kill().ok();
            panic!("{cmd:?} took longer than {secs} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// Runs `mjskill export-mjcf --robot ROBOT --env ENV` to stdout (success asserted) and
/// compiles the printed scene with mjskill's MuJoCo.
pub fn export_mjcf_model(robot: &str, env_id: &str) -> Model {
    // Written with -o into a directory of its own: the mesh and texture files go next to the
    // XML, never into the working directory.
    let dir = scratch_dir(&format!("export-{robot}-{env_id}"));
    let path = dir.join("scene.xml");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args(["export-mjcf", "--robot", robot, "--env", env_id, "-o"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let xml = std::fs::read_to_string(&path).unwrap();
    let files: Vec<(String, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| *p != path)
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap())
        })
        .collect();
    let assets: Vec<(&str, &[u8])> = files
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice()))
        .collect();
    let model = Model::from_xml_string(&xml, &assets).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    model
}

/// Runs `mjskill export-mjcf ARGS -o FILE` (success asserted), compiles FILE with Debian's
/// independent `mujoco-compile` (success and no "error" in its output asserted) and returns
/// the model it printed. `tag` names the temporary directory.
pub fn export_and_mujoco_compile(tag: &str, args: &[&str]) -> String {
    let dir = scratch_dir(tag);
    let xml = dir.join(format!("{tag}.xml"));
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args(args)
        .arg("-o")
        .arg(&xml)
        .status()
        .unwrap();
    assert!(status.success());
    let out = std::process::Command::new("mujoco-compile")
        .arg(&xml)
        .arg(dir.join("scene.txt"))
        .output()
        .expect("mujoco-compile (Debian package libmujoco-samples) must be installed");
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && !text.to_lowercase().contains("error"),
        "mujoco-compile rejected the scene: {text}"
    );
    let printed = std::fs::read_to_string(dir.join("scene.txt")).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    printed
}

/// Asserts that `got` equals `want` element by element within `tol` (same length).
pub fn close(got: &[f32], want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (*g as f64 - w).abs() < tol,
            "{what}[{k}]: got {g}, want {w}"
        );
    }
}

/// A JSON array of numbers as `f32`s (an action recorded from ManiSkill).
pub fn json_f32s(v: &serde_json::Value) -> Vec<f32> {
    json_f64s(v).into_iter().map(|x| x as f32).collect()
}

/// A JSON array of numbers as `f64`s.
pub fn json_f64s(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The env `id` with `robot` in control mode `mode`.
pub fn env_in(id: &str, robot: &str, mode: &str) -> mjskill::Env {
    mjskill::make(
        id,
        mjskill::EnvConfig {
            robot: Some(robot.into()),
            control_mode: Some(mode.into()),
            ..Default::default()
        },
    )
    .unwrap()
}

/// The qpos and qvel addresses of the joint named `joint` in `e`'s model.
pub fn joint_addresses(e: &mjskill::Env, joint: &str) -> (usize, usize) {
    let model = e.model();
    let j = model
        .require_id(mjskill::mujoco::ObjType::Joint, joint)
        .unwrap();
    (
        model.jnt_qposadr()[j] as usize,
        model.jnt_dofadr()[j] as usize,
    )
}

/// Writes the pose of the free body whose free joint is `joint` (zero velocity) through the
/// env state: `physics` = [time, qpos (nq), qvel (nv), ...].
pub fn put_free_body(e: &mut mjskill::Env, joint: &str, pos: [f64; 3], quat: [f64; 4]) {
    let (adr, vadr) = joint_addresses(e, joint);
    let nq = e.model().nq();
    let mut st = e.get_state();
    st.physics[1 + adr..1 + adr + 3].copy_from_slice(&pos);
    st.physics[1 + adr + 3..1 + adr + 7].copy_from_slice(&quat);
    st.physics[1 + nq + vadr..1 + nq + vadr + 6].fill(0.0);
    e.set_state(&st).unwrap();
}
