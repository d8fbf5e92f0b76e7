//! The command line under careless and hostile use: no data loss on bad arguments, side
//! outputs that never clobber or cut the recording, clashing rollouts reported, seeds and
//! counts bounded with messages naming the flag and the range, and `fit-primitives` bounded
//! in time on bad meshes.
#![cfg(feature = "cli")]

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::run_within;

fn mjskill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{e}: {} {}", String::from_utf8_lossy(&o.stdout), stderr(o)))
}

/// Files in `d` whose names start with a dot (temporary recordings).
fn leftovers(d: &Path) -> Vec<String> {
    std::fs::read_dir(d)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.starts_with('.'))
        .collect()
}

#[test]
fn bad_arguments_never_touch_an_existing_recording() {
    let d = common::scratch_dir("badargs");
    let out = d.join("existing.mcap");
    std::fs::write(&out, b"precious bytes").unwrap();
    let png = d.join("existing.png");
    std::fs::write(&png, b"precious png").unwrap();
    let cases: &[(&[&str], &str)] = &[
        (&["--env", "Bogus-v1"], "Bogus-v1"),
        (&["--robot", "r2d2"], "r2d2"),
        (&["--control-mode", "pd_telekinesis"], "pd_telekinesis"),
        (&["--obs-mode", "smell"], "smell"),
        (&["--reward-mode", "praise"], "praise"),
        (&["--policy", "telepathy"], "telepathy"),
        (&["--env", "PokeCube-v1", "--robot", "so100"], "so100"),
        (
            &["--seed", "4294967295", "--episodes", "2"],
            "--seed 4294967295",
        ),
        (&["--seed", "4294967296"], "--seed"),
        (&["--episodes", "0"], "--episodes"),
    ];
    for (args, named) in cases {
        let o = run_within(
            {
                let mut c = mjskill();
                c.arg("rollout").args(*args).arg("--out").arg(&out);
                c
            },
            60,
        );
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains(named), "{args:?}: {}", stderr(&o));
        assert!(o.stdout.is_empty());
        assert_eq!(std::fs::read(&out).unwrap(), b"precious bytes", "{args:?}");
        assert_eq!(std::fs::read(&png).unwrap(), b"precious png", "{args:?}");
        assert!(leftovers(&d).is_empty(), "{args:?}: {:?}", leftovers(&d));
    }
    // A good run replaces the file only once it holds an episode, then completely.
    let o = mjskill()
        .args(["rollout", "--episodes", "2", "--no-frame", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let i = json(&mjskill().arg("info").arg(&out).output().unwrap());
    assert_eq!(
        (i["episodes"].as_u64(), i["complete"].as_bool()),
        (Some(2), Some(true))
    );
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
}

#[test]
fn side_pngs_never_clobber_or_cut_the_recording() {
    let d = common::scratch_dir("sidepng");
    // --out x.png: the frame PNG would be the recording itself.
    let out = d.join("x.png");
    let o = mjskill()
        .args(["rollout", "--episodes", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("overwrite the recording itself"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
    // With --no-frame the name is fine.
    let o = mjskill()
        .args(["rollout", "--episodes", "1", "--no-frame", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        json(&mjskill().arg("info").arg(&out).output().unwrap())["episodes"],
        1
    );
    // A directory where the PNG goes: an error before anything is written.
    let out = d.join("run.mcap");
    std::fs::create_dir_all(d.join("run.png")).unwrap();
    let o = mjskill()
        .args(["rollout", "--episodes", "2", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("run.png") && stderr(&o).contains("directory"));
    assert!(!out.exists());
    // A PNG that only fails once the run is under way (a dangling symlink into a missing
    // directory): a warning; every episode is recorded and the file is complete.
    let out = d.join("late.mcap");
    #[cfg(unix)]
    std::os::unix::fs::symlink(d.join("missing/dir/late.png"), d.join("late.png")).unwrap();
    let o = mjskill()
        .args(["rollout", "--episodes", "3", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let s = json(&o);
    assert!(s["frame"].is_null(), "{s}");
    let i = json(&mjskill().arg("info").arg(&out).output().unwrap());
    assert_eq!(
        (i["episodes"].as_u64(), i["complete"].as_bool()),
        (Some(3), Some(true))
    );
    if cfg!(unix)
        && mjskill::make("PickCube-v1", Default::default())
            .unwrap()
            .render()
            .is_ok()
    {
        assert!(stderr(&o).contains("warning"), "{}", stderr(&o));
    }
}

#[test]
fn two_rollouts_on_one_file_are_a_reported_clash() {
    let d = common::scratch_dir("clash");
    let out = d.join("shared.mcap");
    let spawn = || {
        mjskill()
            .args(["rollout", "--episodes", "20", "--no-frame", "--out"])
            .arg(&out)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    // Both start before either has published: the second to publish reports the clash.
    let (a, b) = (spawn(), spawn());
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    let ok = [&a, &b].iter().filter(|o| o.status.success()).count();
    let lost = if a.status.success() { &b } else { &a };
    assert_eq!(ok, 1, "{} / {}", stderr(&a), stderr(&b));
    assert_eq!(lost.status.code(), Some(2));
    assert!(
        stderr(lost).contains("another mjskill rollout"),
        "{}",
        stderr(lost)
    );
    let i = json(&mjskill().arg("info").arg(&out).output().unwrap());
    assert_eq!(
        (i["episodes"].as_u64(), i["complete"].as_bool()),
        (Some(20), Some(true))
    );
    // A loser that got to record was told where its recording was left, not lost.
    assert!(leftovers(&d).len() <= 1, "{}", stderr(lost));
    for l in leftovers(&d) {
        assert!(stderr(lost).contains(&l));
        std::fs::remove_file(d.join(l)).unwrap();
    }
    // One started while the other writes the published file: refused before simulating.
    let mut first = mjskill()
        .args(["rollout", "--episodes", "400", "--no-frame", "--out"])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t = Instant::now();
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let o = mjskill().arg("info").arg(&out).output().unwrap();
        if o.status.success() && json(&o)["complete"] == false {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(120), "no progress");
    }
    let o = run_within(
        {
            let mut c = mjskill();
            c.args(["rollout", "--episodes", "1", "--no-frame", "--out"])
                .arg(&out);
            c
        },
        60,
    );
    first.kill().ok();
    first.wait().ok();
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("another mjskill rollout"),
        "{}",
        stderr(&o)
    );
    // The killed rollout's lock file stays (no one is left to remove it), unlocked: the next
    // rollout to the same name takes it, and removes it when done.
    assert_eq!(leftovers(&d), [".shared.mcap.lock"]);
    let o = run_within(
        {
            let mut c = mjskill();
            c.args(["rollout", "--episodes", "1", "--no-frame", "--out"])
                .arg(&out);
            c
        },
        60,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
}

/// A symlink at the lock path is never written through (issue 48, finding 5): the rollout
/// refuses, naming the link, and the file it points to (here the previous recording) is left
/// whole. A dangling symlink or a name ending in `/` at `--out` is refused before anything is
/// simulated (1000 episodes would take minutes).
#[test]
fn a_symlink_at_the_lock_path_or_the_output_is_refused_untouched() {
    let d = common::scratch_dir("locklink");
    let out = d.join("x.mcap");
    let previous = d.join("previous.mcap");
    std::fs::write(&previous, b"the previous recording").unwrap();
    let lock = d.join(".x.mcap.lock");
    std::os::unix::fs::symlink(&previous, &lock).unwrap();
    let rollout = |out: &Path| {
        let mut c = mjskill();
        c.args(["rollout", "--episodes", "1000", "--no-frame", "--out"])
            .arg(out);
        run_within(c, 60)
    };
    let o = rollout(&out);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains(".x.mcap.lock") && e.contains("symbolic link") && e.contains("previous.mcap"),
        "{e}"
    );
    assert!(!e.contains("another mjskill rollout"), "{e}");
    assert_eq!(std::fs::read(&previous).unwrap(), b"the previous recording");
    assert!(std::fs::symlink_metadata(&lock)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(!out.exists());
    std::fs::remove_file(&lock).unwrap();
    // A dangling symlink at --out, and a name ending in a slash.
    let dangling = d.join("dangling.mcap");
    std::os::unix::fs::symlink(d.join("missing/dir/y.mcap"), &dangling).unwrap();
    let t = Instant::now();
    let o = rollout(&dangling);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("symbolic link"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("another mjskill rollout"));
    let slash = format!("{}/", d.join("z.mcap").display());
    let o = rollout(Path::new(&slash));
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("ends with a slash"), "{}", stderr(&o));
    assert!(
        t.elapsed() < Duration::from_secs(30),
        "refused only after simulating"
    );
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
}

#[test]
fn a_finished_recording_is_never_replaced_by_a_rollout_started_while_it_ran() {
    // Issue 42: A records 200 episodes; B, started while A runs (here before A's first
    // episode is published, where A's file lock could not stop it), is refused at once
    // through the output's lock file, and A's recording is the one left.
    let d = common::scratch_dir("lockfile");
    let out = d.join("same.mcap");
    let a = mjskill()
        .args(["rollout", "--episodes", "200", "--no-frame", "--out"])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while !d.join(".same.mcap.lock").exists() {
        std::thread::sleep(Duration::from_millis(5));
        assert!(t.elapsed() < Duration::from_secs(60), "A took no lock");
    }
    let b = run_within(
        {
            let mut c = mjskill();
            c.args(["rollout", "--episodes", "5", "--no-frame", "--out"])
                .arg(&out);
            c
        },
        60,
    );
    assert_eq!(b.status.code(), Some(2), "{}", stderr(&b));
    assert!(
        stderr(&b).contains("another mjskill rollout") && stderr(&b).contains("same.mcap"),
        "{}",
        stderr(&b)
    );
    assert!(!stderr(&b).contains(".part"), "{}", stderr(&b));
    let a = a.wait_with_output().unwrap();
    assert!(a.status.success(), "{}", stderr(&a));
    let i = json(&mjskill().arg("info").arg(&out).output().unwrap());
    assert_eq!(
        (i["episodes"].as_u64(), i["complete"].as_bool()),
        (Some(200), Some(true))
    );
    assert_eq!(json(&a)["episodes"], 200);
    assert!(leftovers(&d).is_empty(), "{:?}", leftovers(&d));
}

#[test]
fn seeds_are_32_bit_and_never_wrap() {
    for cmd in ["eval", "rollout", "render"] {
        for seed in ["4294967296", "18446744073709551615", "-1"] {
            let o = run_within(
                {
                    let mut c = mjskill();
                    c.args([cmd, "--seed", seed]);
                    c
                },
                30,
            );
            assert_eq!(o.status.code(), Some(2), "{cmd} --seed {seed}");
            let e = stderr(&o);
            assert!(e.contains("--seed") && e.contains("0..=4294967295"), "{e}");
        }
    }
    for cmd in ["eval", "rollout"] {
        let o = run_within(
            {
                let mut c = mjskill();
                c.args([cmd, "--seed", "4294967295", "--episodes", "2"]);
                c
            },
            30,
        );
        assert_eq!(o.status.code(), Some(2), "{cmd}");
        let e = stderr(&o);
        assert!(e.contains("--seed 4294967295 with --episodes 2"), "{e}");
    }
}

#[test]
fn huge_counts_are_range_errors_at_once() {
    let cases: &[(&[&str], &str)] = &[
        (&["eval", "--episodes", "1000000000000"], "--episodes"),
        (
            &["eval", "--episodes", "18446744073709551615"],
            "--episodes",
        ),
        (&["eval", "--episodes", "-1"], "--episodes"),
        (&["rollout", "--episodes", "-3"], "--episodes"),
        (&["bench", "--steps", "1000000000000"], "--steps"),
        (&["bench", "--steps", "0"], "--steps"),
        (&["bench", "--steps", "-5"], "--steps"),
        (&["bench", "--steps", "-inf"], "--steps"),
        (&["eval", "--seed", "-inf"], "--seed"),
        (&["bench", "--envs", "0"], "--envs"),
        (&["bench", "--envs", "-1"], "--envs"),
        (&["bench", "--threads", "0"], "--threads"),
        (&["bench", "--threads", "-2"], "--threads"),
        (&["bench", "--render", "-1"], "--render"),
        (&["replay", "x.mcap", "--tolerance", "nan"], "--tolerance"),
        (&["replay", "x.mcap", "--tolerance", "-1"], "--tolerance"),
        (&["replay", "x.mcap", "--tolerance", "inf"], "--tolerance"),
        (&["replay", "x.mcap", "--tolerance", "-inf"], "--tolerance"),
    ];
    for (args, flag) in cases {
        let o = run_within(
            {
                let mut c = mjskill();
                c.args(*args);
                c
            },
            10,
        );
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(flag), "{args:?}: {e}");
        assert!(!e.contains("unexpected argument"), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{args:?}: {e}");
    }
    // The message names the valid range.
    let o = mjskill()
        .args(["eval", "--episodes", "-1"])
        .output()
        .unwrap();
    assert!(stderr(&o).contains("1..=4294967296"), "{}", stderr(&o));
    let o = mjskill().args(["bench", "--envs", "0"]).output().unwrap();
    assert!(stderr(&o).contains("1..=256"), "{}", stderr(&o));
}

#[cfg(feature = "mesh-tools")]
fn meshes() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill-meshes"))
}

#[cfg(feature = "mesh-tools")]
#[test]
fn mesh_tool_counts_are_range_errors_at_once() {
    let cases: &[(&[&str], &str)] = &[
        (
            &["fit-primitives", "--mesh", "x.stl", "--parts", "1000"],
            "--parts",
        ),
        (
            &["fit-primitives", "--mesh", "x.stl", "--parts", "0"],
            "--parts",
        ),
        (
            &["fit-primitives", "--mesh", "x.stl", "--parts", "-3"],
            "--parts",
        ),
        (
            &["fit-primitives", "--mesh", "x.stl", "--segments", "0"],
            "--segments",
        ),
        (
            &["fit-primitives", "--mesh", "x.stl", "--scale", "-1"],
            "--scale",
        ),
        (
            &["fit-primitives", "--mesh", "x.stl", "--scale", "1e308"],
            "--scale",
        ),
    ];
    for (args, flag) in cases {
        let o = run_within(
            {
                let mut c = meshes();
                c.args(*args);
                c
            },
            10,
        );
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(flag), "{args:?}: {e}");
        assert!(!e.contains("unexpected argument"), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{args:?}: {e}");
    }
}

#[test]
fn bench_reports_the_threads_it_used() {
    let o = run_within(
        {
            let mut c = mjskill();
            // Steps enough for /proc/stat's clock (10 ms ticks) to move during a timed pass.
            c.args(["bench", "--steps", "2000", "--envs", "2", "--threads", "8"]);
            c
        },
        300,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let r = json(&o);
    assert_eq!(r["envs"], 2);
    assert_eq!(
        r["threads"], 2,
        "a VecEnv of 2 envs runs on at most 2 threads: {r}"
    );
    // Each of those threads' busy share of the timed pass: a share of wall time, so in
    // (0, 1] (a little above 1 only from the clocks' granularity).
    let busy = r["vec_thread_busy"]
        .as_array()
        .unwrap_or_else(|| panic!("no vec_thread_busy: {r}"));
    assert_eq!(busy.len(), 2, "{r}");
    for b in busy {
        let b = b.as_f64().unwrap_or_else(|| panic!("not a number: {r}"));
        assert!(b > 0.0 && b <= 1.05, "{r}");
    }
    if std::path::Path::new("/proc/stat").exists() {
        let steal = r["steal_percent"]
            .as_f64()
            .unwrap_or_else(|| panic!("no steal_percent: {r}"));
        assert!((0.0..=100.0).contains(&steal), "{r}");
    }
}

#[test]
fn replay_tolerance_is_a_finite_number_at_least_zero() {
    let d = common::scratch_dir("tol");
    let f = d.join("t.mcap");
    let o = mjskill()
        .args(["rollout", "--episodes", "1", "--no-frame", "--out"])
        .arg(&f)
        .output()
        .unwrap();
    assert!(o.status.success());
    let o = mjskill()
        .args(["replay", "--tolerance", "0"])
        .arg(&f)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(json(&o)["tolerance"], 0.0);
    for bad in [f64::NAN, -1.0, f64::INFINITY] {
        let e = mjskill::record::replay::replay(&f, bad, false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--tolerance"), "{e}");
    }
}

#[test]
fn export_mjcf_defaults_to_the_envs_robot() {
    // Printed to stdout, the scene's mesh files are not written into the working directory.
    let cwd = common::scratch_dir("export-cwd");
    let o = mjskill()
        .current_dir(&cwd)
        .args(["export-mjcf", "--env", "PickCubeSO100-v1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(&cwd).unwrap().count(), 0);
    assert!(stderr(&o).contains("use -o FILE.xml"), "{}", stderr(&o));
    std::fs::remove_dir_all(&cwd).unwrap();
    let xml = String::from_utf8_lossy(&o.stdout);
    assert!(
        xml.contains("<mujoco") && xml.contains("Jaw"),
        "so100's jaw links"
    );
    let o = mjskill()
        .args(["export-mjcf", "--env", "PokeCube-v1", "--robot", "so100"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("panda, fetch"), "{}", stderr(&o));
}

/// An ASCII STL of the given triangles.
#[cfg(feature = "mesh-tools")]
fn stl(tris: &[[[f64; 3]; 3]]) -> String {
    let mut s = String::from("solid t\n");
    for t in tris {
        s += "facet normal 0 0 0\nouter loop\n";
        for v in t {
            s += &format!("vertex {} {} {}\n", v[0], v[1], v[2]);
        }
        s += "endloop\nendfacet\n";
    }
    s + "endsolid t\n"
}

#[cfg(feature = "mesh-tools")]
fn fit(d: &Path, name: &str, mesh: &[u8], args: &[&str], secs: u64) -> Output {
    let p = d.join(name);
    std::fs::write(&p, mesh).unwrap();
    run_within(
        {
            let mut c = meshes();
            c.args(["fit-primitives", "--mesh"]).arg(&p).args(args);
            c
        },
        secs,
    )
}

#[cfg(feature = "mesh-tools")]
#[test]
fn fit_primitives_rejects_bad_meshes_and_stays_bounded() {
    let d = common::scratch_dir("fit");
    let tet = |s: f64| {
        let (o, x, y, z) = ([0.0; 3], [s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]);
        vec![[o, y, x], [o, x, z], [o, z, y], [x, y, z]]
    };
    // Non-finite and huge coordinates: errors at once (they used to hang).
    for (name, bad) in [("nan", "nan"), ("inf", "inf"), ("big", "1e300")] {
        let mut text = stl(&tet(0.1));
        text = text.replacen("vertex 0 0.1 0", &format!("vertex 0 {bad} 0"), 1);
        let o = fit(&d, &format!("{name}.stl"), text.as_bytes(), &[], 10);
        assert_eq!(o.status.code(), Some(2), "{name}");
        let e = stderr(&o);
        assert!(
            e.contains("not finite") || e.contains("±1e6"),
            "{name}: {e}"
        );
    }
    // A huge scale: an error, not a hang.
    let o = fit(
        &d,
        "tet.stl",
        stl(&tet(0.1)).as_bytes(),
        &["--scale", "1e308"],
        10,
    );
    assert_eq!(o.status.code(), Some(2));
    // Coordinates beyond ±1e6 m once scaled: an error naming the bound.
    let o = fit(
        &d,
        "tet10.stl",
        stl(&tet(10.0)).as_bytes(),
        &["--scale", "1e6"],
        10,
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("±1e6"), "{}", stderr(&o));
    // Degenerate meshes: a flat square and a single point are errors, not size="0 0 0".
    let flat = stl(&[
        [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.1, 0.0]],
        [[0.0, 0.0, 0.0], [0.1, 0.1, 0.0], [0.0, 0.1, 0.0]],
    ]);
    let point = stl(&[[[0.2, 0.2, 0.2]; 3]]);
    for (name, mesh, args) in [
        ("flat.stl", &flat, &["--shape", "box"][..]),
        ("flat2.stl", &flat, &["--shape", "cylinder"][..]),
        ("point.stl", &point, &[][..]),
    ] {
        let o = fit(&d, name, mesh.as_bytes(), args, 20);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{name}: {}",
            String::from_utf8_lossy(&o.stdout)
        );
        assert!(stderr(&o).contains("degenerate"), "{name}: {}", stderr(&o));
        assert!(!String::from_utf8_lossy(&o.stdout).contains("NaN"));
    }
    // A 100 KB binary STL of 2,000 large triangles: bounded samples, seconds not minutes.
    let mut b = vec![0u8; 80];
    let n = 2000u32;
    b.extend(n.to_le_bytes());
    for k in 0..n {
        let z = k as f32 * 0.001;
        b.extend([0u8; 12]);
        for v in [[0.0f32, 0.0, z], [1.0, 0.0, z], [0.0, 1.0, z + 0.5]] {
            for c in v {
                b.extend(c.to_le_bytes());
            }
        }
        b.extend([0u8; 2]);
    }
    assert!(b.len() > 100_000);
    let t = Instant::now();
    let o = fit(&d, "big.stl", &b, &["--parts", "3"], 120);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(t.elapsed() < Duration::from_secs(90), "{:?}", t.elapsed());
    // The most parts allowed end too.
    let o = fit(
        &d,
        "tet64.stl",
        stl(&tet(0.1)).as_bytes(),
        &["--parts", "64"],
        120,
    );
    assert!(o.status.success(), "{}", stderr(&o));
}
