//! Datasets: importing ManiSkill's sample demos (tests/data/maniskill_demos, copied from
//! shared/reference/maniskill/demos), exporting to ManiSkill's trajectory format (round trip)
//! and to LeRobotDataset v3 (read back with pyarrow and decoded with PyAV, independent of
//! mjskill's writers), and bad input.
//!
//! The Python checks use the venv `.ci/setup` creates (`.ci/venv`); without it they print a
//! note and pass, unless `MJSKILL_REQUIRE_PYTHON` is set (`.ci/run` sets it).
#![cfg(all(feature = "datasets", feature = "cli"))]
mod common;
use std::path::{Path, PathBuf};
use std::process::Command;

use mjskill::datasets::export;
use mjskill::datasets::import::{self, ImportArgs, ReplayBy};
use mjskill::datasets::maniskill_h5;
use mjskill::datasets::DatasetError;
use mjskill::record::{self, Recorder};
use mjskill::{make, EnvConfig, SimConfig};

fn demos() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/maniskill_demos")
}

/// Names in `dir` (temporaries included: a failed command must leave none).
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn import(
    h5: &Path,
    json: Option<&Path>,
    out: &Path,
    by: ReplayBy,
) -> Result<import::ImportReport, DatasetError> {
    import::run(&ImportArgs {
        h5: h5.to_path_buf(),
        json: json.map(Path::to_path_buf),
        out: out.to_path_buf(),
        by,
        sim: SimConfig::default(),
    })
}

/// (file, [(ManiSkill success, by actions, by states, first divergence step)] per episode).
type Expected = (&'static str, [(bool, bool, bool, Option<usize>); 3]);

/// The figures the import reports for the sample demos (docs/datasets.md, "Import ManiSkill demos").
const EXPECTED: [Expected; 4] = [
    ("PickCube-v1/trajectory.h5", [(true, true, true, None); 3]),
    (
        "PickCube-v1/trajectory.none.pd_ee_delta_pose.physx_cpu.h5",
        [(true, true, true, None); 3],
    ),
    (
        "PlaceSphere-v1/trajectory.h5",
        [
            (false, true, false, None),
            (true, true, true, None),
            (false, false, false, None),
        ],
    ),
    (
        "PokeCube-v1/trajectory.h5",
        [
            (true, true, true, Some(123)),
            (true, true, true, Some(113)),
            (true, true, true, None),
        ],
    ),
];

#[test]
fn sample_demos_import_with_the_reported_success() {
    let dir = common::scratch_dir("import");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(demos().join("demos_summary.json")).unwrap())
            .unwrap();
    for (file, want) in EXPECTED {
        let h5 = demos().join(file);
        for by in [ReplayBy::Actions, ReplayBy::States] {
            let out = dir.join(format!("{}-{}.mcap", file.replace('/', "_"), by.name()));
            let r = import(&h5, None, &out, by).unwrap_or_else(|e| panic!("{file}: {e}"));
            let got: Vec<_> = r
                .episodes
                .iter()
                .map(|e| {
                    (
                        e.maniskill_success,
                        e.by_actions_success,
                        e.by_states_success,
                        e.first_divergence_step,
                    )
                })
                .collect();
            eprintln!("{file} by {}: {got:?}", by.name());
            assert_eq!(got, want, "{file}");
            // By states, mjskill's success flag is ManiSkill's at every step.
            assert!(
                r.episodes
                    .iter()
                    .all(|e| e.by_states_success_mismatches == 0),
                "{file}"
            );
            // ManiSkill's figures are those of the demos' own summary.
            let env = file.split('/').next().unwrap();
            if !file.contains("pd_ee") {
                for (e, s) in r
                    .episodes
                    .iter()
                    .zip(summary[env]["episodes"].as_array().unwrap())
                {
                    assert_eq!(e.maniskill_success, s["success"].as_bool().unwrap());
                    assert_eq!(e.steps as u64, s["elapsed_steps"].as_u64().unwrap());
                    assert_eq!(e.seed, s["seed"].as_u64());
                }
            }
            // The recording holds every episode, step for step.
            let rec = record::read(&out).unwrap();
            assert!(rec.complete);
            let eps: Vec<_> = rec.finished().collect();
            assert_eq!(eps.len(), 3);
            for (e, rep) in eps.iter().zip(&r.episodes) {
                assert_eq!(e.steps.len(), rep.steps);
                assert_eq!(e.seed, rep.seed);
            }
            assert_eq!(rec.meta.env_id, r.env_id);
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Largest |a - b| relative to max(1, |a|) over two trajectories' env_states.
fn state_error(a: &maniskill_h5::EpisodeData, b: &maniskill_h5::EpisodeData) -> f64 {
    assert_eq!(a.env_states.len(), b.env_states.len());
    let mut worst = 0.0f64;
    for (sa, sb) in a.env_states.iter().zip(&b.env_states) {
        assert!(
            sa.actors.keys().eq(sb.actors.keys()) || {
                let mut x: Vec<_> = sa.actors.keys().collect();
                let mut y: Vec<_> = sb.actors.keys().collect();
                x.sort();
                y.sort();
                x == y
            }
        );
        for (name, va) in &sa.actors {
            for (x, y) in va.iter().zip(&sb.actors[name]) {
                worst = worst.max((x - y).abs() / x.abs().max(1.0));
            }
        }
        for (name, va) in &sa.articulations {
            let vb = &sb.articulations[name];
            assert_eq!(va.len(), vb.len());
            for (x, y) in va.iter().zip(vb) {
                worst = worst.max((x - y).abs() / x.abs().max(1.0));
            }
        }
    }
    worst
}

#[test]
fn imported_demos_round_trip_to_maniskill_format() {
    let dir = common::scratch_dir("roundtrip");
    for file in [
        "PickCube-v1/trajectory.h5",
        "PlaceSphere-v1/trajectory.h5",
        "PokeCube-v1/trajectory.h5",
        "PickCube-v1/trajectory.none.pd_ee_delta_pose.physx_cpu.h5",
    ] {
        let h5 = demos().join(file);
        let mcap = dir.join("demo.mcap");
        let rep = import(&h5, None, &mcap, ReplayBy::States).unwrap();
        let out = dir.join("traj.h5");
        let s = export::to_maniskill(&mcap, &out, None).unwrap();
        assert_eq!(s.episodes, 3);
        assert_eq!(listing(&dir), ["demo.mcap", "traj.h5", "traj.json"]);
        let orig = maniskill_h5::read(&h5, None).unwrap_or_else(|e| panic!("{file}: {e}"));
        let back = maniskill_h5::read(&out, None).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(back.json.env_info.env_id, orig.json.env_info.env_id);
        assert_eq!(back.episodes.len(), orig.episodes.len());
        for (k, (a, b)) in orig.episodes.iter().zip(&back.episodes).enumerate() {
            let (ia, ib) = (&orig.json.episodes[k], &back.json.episodes[k]);
            assert_eq!(ia.seed(), ib.seed(), "{file} {k}");
            assert_eq!(ia.control_mode, ib.control_mode);
            assert_eq!(ia.elapsed_steps, ib.elapsed_steps);
            assert_eq!(a.actions, b.actions, "{file} {k}: actions bitwise");
            assert_eq!(a.action_dim, b.action_dim);
            assert_eq!(a.truncated, b.truncated, "{file} {k}");
            // env_states: ManiSkill's names, every value equal within float32.
            let err = state_error(a, b);
            assert!(
                err <= 2.0 * f32::EPSILON as f64,
                "{file} {k}: env_states differ by {err}"
            );
            // success and terminated are mjskill's, recomputed from ManiSkill's states: they
            // differ from ManiSkill's flags exactly where the import reported.
            let sa = a.success.as_ref().unwrap();
            let sb = b.success.as_ref().unwrap();
            let mismatches = sa.iter().zip(sb).filter(|(x, y)| x != y).count();
            assert_eq!(
                mismatches, rep.episodes[k].by_states_success_mismatches,
                "{file} {k}"
            );
            assert_eq!(b.terminated, *sb);
            // The actor datasets are listed in ManiSkill's scene order.
            let names: Vec<_> = b.env_states[0].actors.keys().cloned().collect();
            let env = make(&orig.json.env_info.env_id, EnvConfig::default()).unwrap();
            let order: Vec<String> = env.actor_names().iter().map(|s| s.to_string()).collect();
            assert_eq!(names, order);
        }
        // h5py (as ManiSkill reads it) sees the same layout: groups in ManiSkill's order,
        // numpy bools, float32 actions.
        if let Some(py) = python() {
            let script = "import h5py, json, sys\n\
                f = h5py.File(sys.argv[1], 'r')\n\
                g = f['traj_0']\n\
                print(json.dumps({'trajs': list(f), 'actors': list(g['env_states/actors']),\
                'success': str(g['success'].dtype), 'actions': str(g['actions'].dtype),\
                'shape': list(g['actions'].shape)}))";
            let o = Command::new(py)
                .args(["-c", script])
                .arg(&out)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            let env = make(&orig.json.env_info.env_id, EnvConfig::default()).unwrap();
            assert_eq!(
                v["trajs"],
                serde_json::json!(["traj_0", "traj_1", "traj_2"])
            );
            assert_eq!(v["actors"], serde_json::json!(env.actor_names()));
            assert_eq!(v["success"], "bool");
            assert_eq!(v["actions"], "float32");
            assert_eq!(
                v["shape"],
                serde_json::json!([orig.episodes[0].steps(), orig.episodes[0].action_dim])
            );
        }
        std::fs::remove_file(&out).unwrap();
        std::fs::remove_file(out.with_extension("json")).unwrap();
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Records `episodes` episodes of `steps` random-ish steps of PickCube (state obs), with the
/// human camera's video when `video`.
fn record_rollout(path: &Path, episodes: usize, steps: usize, video: bool) -> Vec<Vec<u8>> {
    let mut env = make("PickCube-v1", EnvConfig::default()).unwrap();
    let mut rec = Recorder::create(path, &env).unwrap();
    if video {
        rec.enable_video("render_camera").unwrap();
    }
    let (w, h) = env.render_size();
    let dim = env.action_space().shape[0];
    let mut frames = Vec::new();
    for k in 0..episodes {
        rec.reset(&mut env, Some(40 + k as u64)).unwrap();
        if video {
            let rgb = env.render().unwrap().to_vec();
            rec.record_frame(&rgb, w, h).unwrap();
            frames.push(rgb);
        }
        for t in 0..steps {
            let a: Vec<f32> = (0..dim)
                .map(|i| (((t * 7 + i * 3 + k) % 11) as f32 / 5.0 - 1.0) * 0.5)
                .collect();
            rec.step(&mut env, &a).unwrap();
            if video {
                let rgb = env.render().unwrap().to_vec();
                rec.record_frame(&rgb, w, h).unwrap();
                frames.push(rgb);
            }
        }
        rec.end_episode(false).unwrap();
    }
    rec.finish().unwrap();
    frames
}

#[test]
fn exported_rollout_states_are_the_envs() {
    let dir = common::scratch_dir("rollout");
    let mcap = dir.join("run.mcap");
    record_rollout(&mcap, 2, 6, false);
    let out = dir.join("run.h5");
    export::to_maniskill(&mcap, &out, None).unwrap();
    let t = maniskill_h5::read(&out, None).unwrap();
    let rec = record::read(&mcap).unwrap();
    assert_eq!(t.json.env_info.env_id, "PickCube-v1");
    assert_eq!(
        t.json.env_info.env_kwargs["control_mode"],
        "pd_joint_delta_pos"
    );
    let mut env = make("PickCube-v1", EnvConfig::default()).unwrap();
    for (k, (ep, r)) in t.episodes.iter().zip(rec.finished()).enumerate() {
        assert_eq!(t.json.episodes[k].seed(), Some(40 + k as u64));
        assert_eq!(ep.steps(), 6);
        env.reset(Some(40 + k as u64));
        let f32s = |v: Vec<f64>| v.into_iter().map(|x| x as f32 as f64).collect::<Vec<_>>();
        assert_eq!(
            f32s(ep.env_states[0].flat()),
            f32s(env.get_state_dict().flat())
        );
        for t in 0..6 {
            env.step(ep.action(t)).unwrap();
            assert_eq!(
                f32s(ep.env_states[t + 1].flat()),
                f32s(env.get_state_dict().flat()),
                "episode {k} step {t}"
            );
        }
        // obs: row 0 after the reset, then after every step, as recorded.
        let (obs, d) = ep.obs.as_ref().unwrap();
        assert_eq!(&obs[..*d], &r.initial_obs[..]);
        assert_eq!(&obs[6 * d..], &r.steps[5].obs[..]);
        assert_eq!(ep.rewards.as_ref().unwrap()[5], r.steps[5].reward);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

fn python() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/venv/bin/python");
    let ok = p.exists()
        && Command::new(&p)
            .args(["-c", "import pyarrow, pandas, av, h5py"])
            .status()
            .is_ok_and(|s| s.success());
    if ok {
        return Some(p);
    }
    assert!(
        std::env::var_os("MJSKILL_REQUIRE_PYTHON").is_none(),
        "{} with pyarrow, pandas, av and h5py is missing: run `bash .ci/setup`",
        p.display()
    );
    eprintln!(
        "note: LeRobot read-back skipped: run `bash .ci/setup` to create {}",
        p.display()
    );
    None
}

/// Reads a LeRobot v3 dataset with pyarrow / pandas and decodes its videos with PyAV (FFmpeg's
/// decoder): prints one JSON line of what it found.
const READER: &str = r#"
import json, sys, pathlib
import pyarrow.parquet as pq, pandas as pd, av
root = pathlib.Path(sys.argv[1])
info = json.loads((root / "meta/info.json").read_text())
stats = json.loads((root / "meta/stats.json").read_text())
data = pq.read_table(root / info["data_path"].format(chunk_index=0, file_index=0))
eps = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
tasks = pd.read_parquet(root / "meta/tasks.parquet")
out = {"info": info, "columns": data.column_names, "rows": data.num_rows,
       "types": {f.name: str(f.type) for f in data.schema},
       "episodes": eps, "tasks": list(tasks.index), "task_index": [int(x) for x in tasks["task_index"]],
       "stats_keys": sorted(stats), "data": {c: data.column(c).to_pylist() for c in
       ["timestamp", "frame_index", "episode_index", "index", "next.done", "action", "observation.state"]},
       "videos": {}}
for key, ft in info["features"].items():
    if ft["dtype"] != "video":
        continue
    path = root / info["video_path"].format(video_key=key, chunk_index=0, file_index=0)
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        cc = s.codec_context
        frames, pts, means = 0, [], []
        for f in c.decode(s):
            frames += 1
            pts.append(float(f.pts * s.time_base))
            a = f.to_ndarray(format="rgb24")
            means.append(float(a.mean()))
        out["videos"][key] = {"codec": cc.name, "profile": cc.profile, "has_b_frames": bool(cc.has_b_frames),
                              "width": cc.width, "height": cc.height, "frames": frames, "pts": pts,
                              "means": means, "pix_fmt": cc.pix_fmt}
print(json.dumps(out))
"#;

#[test]
fn lerobot_export_reads_back_with_pyarrow_and_pyav() {
    let dir = common::scratch_dir("lerobot");
    let mcap = dir.join("run.mcap");
    let frames = record_rollout(&mcap, 2, 9, true);
    let ds = dir.join("ds");
    let s = mjskill::datasets::lerobot::write(&mcap, &ds, Some(true)).unwrap();
    assert_eq!((s.episodes, s.steps), (2, 18));
    assert_eq!(s.videos, [("render_camera".to_string(), 18)]);
    for p in mjskill::datasets::lerobot::layout(&["render_camera"]) {
        assert!(ds.join(&p).is_file(), "{}", p.display());
    }
    // Without --video, no videos directory; a non-empty output directory is refused.
    let ds2 = dir.join("ds2");
    mjskill::datasets::lerobot::write(&mcap, &ds2, Some(false)).unwrap();
    assert!(!ds2.join("videos").exists());
    let e = mjskill::datasets::lerobot::write(&mcap, &ds2, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("not an empty directory"), "{e}");
    // An existing empty directory is filled.
    let ds3 = dir.join("ds3");
    std::fs::create_dir(&ds3).unwrap();
    mjskill::datasets::lerobot::write(&mcap, &ds3, Some(false)).unwrap();
    assert!(ds3.join("meta/info.json").is_file());

    let Some(py) = python() else { return };
    let o = Command::new(py)
        .arg("-c")
        .arg(READER)
        .arg(&ds)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let info = &v["info"];
    assert_eq!(info["codebase_version"], "v3.0");
    assert_eq!(info["fps"], 20);
    assert_eq!(info["robot_type"], "panda");
    assert_eq!(info["total_episodes"], 2);
    assert_eq!(info["total_frames"], 18);
    let f = &info["features"];
    assert_eq!(f["action"]["shape"], serde_json::json!([8]));
    assert_eq!(f["action"]["names"].as_array().unwrap().len(), 8);
    assert_eq!(f["observation.state"]["dtype"], "float32");
    assert_eq!(
        f["observation.images.render_camera"]["shape"],
        serde_json::json!([512, 512, 3])
    );
    for c in [
        "observation.state",
        "action",
        "next.reward",
        "next.done",
        "next.success",
        "timestamp",
        "frame_index",
        "episode_index",
        "index",
        "task_index",
    ] {
        assert!(
            v["columns"].as_array().unwrap().iter().any(|x| x == c),
            "column {c}"
        );
        assert!(
            v["stats_keys"].as_array().unwrap().iter().any(|x| x == c),
            "stats {c}"
        );
    }
    let ty = v["types"]["action"].as_str().unwrap();
    assert!(
        ty.starts_with("fixed_size_list<") && ty.ends_with(": float not null>[8]"),
        "{ty}"
    );
    assert_eq!(v["rows"], 18);
    let d = &v["data"];
    for i in 0..18usize {
        let t = i % 9;
        assert_eq!(d["index"][i], i);
        assert_eq!(d["frame_index"][i], t);
        assert_eq!(d["episode_index"][i], i / 9);
        assert_eq!(
            d["timestamp"][i].as_f64().unwrap(),
            (t as f32 / 20.0) as f64,
            "1/fps grid"
        );
        assert_eq!(d["next.done"][i], t == 8);
    }
    // Rows hold the recorded actions and the obs before them.
    let rec = record::read(&mcap).unwrap();
    let ep1 = rec.finished().nth(1).unwrap();
    let a: Vec<f32> = serde_json::from_value(d["action"][9 + 4].clone()).unwrap();
    assert_eq!(a, ep1.steps[4].action);
    let o0: Vec<f32> = serde_json::from_value(d["observation.state"][9].clone()).unwrap();
    assert_eq!(o0, ep1.initial_obs);
    assert_eq!(
        v["tasks"][0],
        "Grasp the red cube and move it to the goal position."
    );
    let eps = v["episodes"].as_array().unwrap();
    assert_eq!(eps.len(), 2);
    assert_eq!(eps[1]["dataset_from_index"], 9);
    assert_eq!(eps[1]["length"], 9);
    assert_eq!(
        eps[1]["videos/observation.images.render_camera/from_timestamp"],
        0.45
    );
    // The video: H.264 without B-frames, one frame per row on the 1/fps grid, and the
    // pictures are the rendered ones (mean brightness within 2 levels).
    let vid = &v["videos"]["observation.images.render_camera"];
    assert_eq!(vid["codec"], "h264");
    assert_eq!(vid["has_b_frames"], false);
    assert!(
        vid["profile"].as_str().unwrap().contains("Baseline"),
        "{}",
        vid["profile"]
    );
    assert_eq!(
        (vid["width"].as_u64(), vid["height"].as_u64()),
        (Some(512), Some(512))
    );
    assert_eq!(vid["frames"], 18);
    for i in 0..18usize {
        assert!((vid["pts"][i].as_f64().unwrap() - i as f64 / 20.0).abs() < 1e-6);
        // Row i's frame: episode i / 9, frame i % 9 of that episode (10 recorded per episode).
        let src = &frames[(i / 9) * 10 + i % 9];
        let mean = src.iter().map(|&x| x as f64).sum::<f64>() / src.len() as f64;
        let got = vid["means"][i].as_f64().unwrap();
        assert!(
            (got - mean).abs() < 2.0,
            "frame {i}: mean {got} vs rendered {mean}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_input_is_a_clear_error_and_leaves_nothing() {
    let dir = common::scratch_dir("bad");
    let src = demos().join("PickCube-v1");
    // A truncated h5.
    let bytes = std::fs::read(src.join("trajectory.h5")).unwrap();
    std::fs::write(dir.join("cut.h5"), &bytes[..bytes.len() / 2]).unwrap();
    std::fs::copy(src.join("trajectory.json"), dir.join("cut.json")).unwrap();
    let out = dir.join("out.mcap");
    let e = import(&dir.join("cut.h5"), None, &out, ReplayBy::Actions)
        .unwrap_err()
        .to_string();
    assert!(e.contains("cut.h5") && e.contains("HDF5"), "{e}");
    assert_eq!(listing(&dir), ["cut.h5", "cut.json"]);
    // A wrong env id in the json.
    let json = std::fs::read_to_string(src.join("trajectory.json")).unwrap();
    std::fs::write(
        dir.join("wrong.json"),
        json.replace("\"PickCube-v1\"", "\"PickCube-v9\""),
    )
    .unwrap();
    let e = import(
        &src.join("trajectory.h5"),
        Some(&dir.join("wrong.json")),
        &out,
        ReplayBy::States,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("\"PickCube-v9\"") && e.contains("PlaceSphere-v1"),
        "{e}"
    );
    // A json listing other episodes than the h5 holds.
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let mut two = v.clone();
    two["episodes"].as_array_mut().unwrap().pop();
    std::fs::write(dir.join("two.json"), two.to_string()).unwrap();
    let e = import(
        &src.join("trajectory.h5"),
        Some(&dir.join("two.json")),
        &out,
        ReplayBy::Actions,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("3 traj_<k> groups") && e.contains("2 episodes"),
        "{e}"
    );
    assert_eq!(
        listing(&dir),
        ["cut.h5", "cut.json", "two.json", "wrong.json"]
    );
    // A recording without frames exported with video requested.
    let mcap = dir.join("run.mcap");
    record_rollout(&mcap, 1, 3, false);
    let e = mjskill::datasets::lerobot::write(&mcap, &dir.join("ds"), Some(true))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no camera frames") && e.contains("--video"),
        "{e}"
    );
    assert_eq!(
        listing(&dir),
        ["cut.h5", "cut.json", "run.mcap", "two.json", "wrong.json"]
    );
    // The CLI says the same and exits non-zero.
    let o = Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args([
            "export",
            mcap.to_str().unwrap(),
            "--format",
            "lerobot",
            "--video",
            "yes",
            "-o",
        ])
        .arg(dir.join("ds"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("no camera frames"));
    let o = Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args(["export", mcap.to_str().unwrap(), "--format", "parquet"])
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("valid: maniskill, lerobot"));
    assert_eq!(
        listing(&dir),
        ["cut.h5", "cut.json", "run.mcap", "two.json", "wrong.json"]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cli_imports_and_exports() {
    let dir = common::scratch_dir("cli");
    let out = dir.join("demos.mcap");
    let o = Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .arg("import-maniskill")
        .arg(demos().join("PokeCube-v1/trajectory.h5"))
        .args(["--by", "states", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["env_id"], "PokeCube-v1");
    assert_eq!(r["by"], "states");
    for k in [
        "maniskill_success",
        "by_actions_success",
        "by_states_success",
        "first_divergence_step",
    ] {
        assert!(r["episodes"][0].get(k).is_some(), "{k}");
    }
    let o = Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .arg("export")
        .arg(&out)
        .args(["--format", "maniskill", "-o"])
        .arg(dir.join("t.h5"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("t.json").is_file());
    let o = Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args(["import-maniskill", "x.h5", "--by", "frames", "--out"])
        .arg(dir.join("x.mcap"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("\"frames\"") && err.contains("valid: actions, states"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn rollout_records_sensor_camera_video_that_exports_to_lerobot() {
    let dir = common::scratch_dir("camera");
    let out = dir.join("cam.mcap");
    let mj = || Command::new(env!("CARGO_BIN_EXE_mjskill"));
    // Without a colour obs mode the camera is refused before anything is written.
    let o = mj()
        .args([
            "rollout",
            "--episodes",
            "1",
            "--no-frame",
            "--camera",
            "base_camera",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--obs-mode rgb"), "{err}");
    let o = mj()
        .args([
            "rollout",
            "--episodes",
            "1",
            "--no-frame",
            "--obs-mode",
            "rgb",
            "--camera",
            "top",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("valid: base_camera"),
        "{err}"
    );
    assert!(listing(&dir).is_empty());
    let o = mj()
        .args([
            "rollout",
            "--episodes",
            "2",
            "--no-frame",
            "--obs-mode",
            "rgb",
            "--camera",
            "base_camera",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let steps = s["steps"].as_u64().unwrap();
    assert_eq!(s["video_frames"].as_u64().unwrap(), steps + 2);
    let raw = record::read_raw(&out).unwrap();
    let frames = raw
        .messages
        .iter()
        .filter(|m| m.topic == "/base_camera/video")
        .count();
    assert_eq!(frames as u64, steps + 2);
    assert!(raw
        .messages
        .iter()
        .filter(|m| m.topic == "/base_camera/video")
        .all(|m| m.schema == "foxglove.CompressedVideo"));
    let ds = dir.join("ds");
    let sum = mjskill::datasets::lerobot::write(&out, &ds, None).unwrap();
    assert_eq!(sum.videos, [("base_camera".to_string(), steps as usize)]);
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(ds.join("meta/info.json")).unwrap()).unwrap();
    assert_eq!(
        info["features"]["observation.images.base_camera"]["shape"],
        serde_json::json!([128, 128, 3])
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Rewrites a recording as mjskill wrote it before H.264 video: the camera's frames as PNG
/// `foxglove.CompressedImage` messages on `/render_camera/image` (decoded from the H.264
/// frames with OpenH264, re-encoded losslessly), every other record as it was.
fn to_png_recording(src: &Path, dst: &Path) -> Vec<Vec<u8>> {
    use base64::Engine;
    use openh264::formats::YUVSource;
    let b64 = base64::engine::general_purpose::STANDARD;
    let raw = record::read_raw(src).unwrap();
    let mut w = mcap::WriteOptions::new()
        .profile(raw.profile.clone())
        .library(raw.library.clone())
        .create(std::io::BufWriter::new(std::fs::File::create(dst).unwrap()))
        .unwrap();
    w.write_metadata(&mcap::records::Metadata {
        name: "mjskill".into(),
        metadata: raw.metadata.clone(),
    })
    .unwrap();
    let mut channels = std::collections::BTreeMap::new();
    let mut dec = openh264::decoder::Decoder::new().unwrap();
    let mut pngs = Vec::new();
    let mut episode = 0;
    for (seq, m) in raw.messages.iter().enumerate() {
        let (topic, schema, data) = if m.schema == "foxglove.CompressedVideo" {
            let mut v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            let unit = b64.decode(v["data"].as_str().unwrap()).unwrap();
            let pic = dec.decode(&unit).unwrap().expect("one picture per frame");
            let (pw, ph) = pic.dimensions();
            let mut rgb = vec![0; pw * ph * 3];
            pic.write_rgb8(&mut rgb);
            let mut png = Vec::new();
            mjskill::record::image::encode_png(&rgb, pw, ph, &mut png).unwrap();
            v["data"] = b64.encode(&png).into();
            v["format"] = "png".into();
            pngs.push(rgb);
            (
                record::TOPIC_RENDER_IMAGE.to_string(),
                "foxglove.CompressedImage",
                serde_json::to_vec(&v).unwrap(),
            )
        } else {
            (m.topic.clone(), m.schema.as_str(), m.data.clone())
        };
        if m.topic == record::TOPIC_EPISODE {
            w.write_metadata(&mcap::records::Metadata {
                name: format!("episode-{episode}"),
                metadata: raw.episode_metadata[episode].clone(),
            })
            .unwrap();
            episode += 1;
        }
        let id = match channels.get(&topic) {
            Some(&id) => id,
            None => {
                let sid = w.add_schema(schema, "jsonschema", b"{}").unwrap();
                let id = w
                    .add_channel(sid, &topic, "json", &std::collections::BTreeMap::new())
                    .unwrap();
                channels.insert(topic.clone(), id);
                id
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: seq as u32,
            log_time: m.log_time,
            publish_time: m.log_time,
        };
        w.write_to_known_channel(&header, &data).unwrap();
    }
    w.finish().unwrap();
    pngs
}

#[test]
fn recordings_with_png_frames_still_read_and_export_to_lerobot() {
    let dir = common::scratch_dir("png");
    let h264 = dir.join("h264.mcap");
    record_rollout(&h264, 2, 4, true);
    let old = dir.join("old.mcap");
    let pngs = to_png_recording(&h264, &old);
    assert_eq!(pngs.len(), 10);
    // The old file reads as before.
    let (a, b) = (record::read(&h264).unwrap(), record::read(&old).unwrap());
    assert!(b.complete);
    assert_eq!(a.episodes, b.episodes);
    let raw = record::read_raw(&old).unwrap();
    assert_eq!(
        raw.messages
            .iter()
            .filter(|m| m.topic == record::TOPIC_RENDER_IMAGE)
            .count(),
        10
    );
    // Its PNG frames are encoded to H.264 by the LeRobot export: one per row.
    let ds = dir.join("ds");
    let s = mjskill::datasets::lerobot::write(&old, &ds, Some(true)).unwrap();
    assert_eq!(s.videos, [("render_camera".to_string(), 8)]);
    let mp4 = ds.join("videos/observation.images.render_camera/chunk-000/file-000.mp4");
    assert!(std::fs::metadata(&mp4).unwrap().len() > 1000);
    if let Some(py) = python() {
        let script = "import av, sys\n\
            c = av.open(sys.argv[1]); s = c.streams.video[0]\n\
            print(sum(1 for _ in c.decode(s)), s.codec_context.name, s.codec_context.has_b_frames)";
        let o = Command::new(py)
            .args(["-c", script])
            .arg(&mp4)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), "8 h264 False");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

fn mjskill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
}

/// Runs `cmd`, expects a clean failure (an exit code, no signal) and returns its stderr.
fn fails(cmd: &mut Command) -> String {
    let o = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        o.status.code().is_some_and(|c| c != 0),
        "{cmd:?} should fail with an exit code: {:?} {err}",
        o.status
    );
    err
}

/// The file type of `p` (not following a symbolic link).
fn file_type(p: &Path) -> std::fs::FileType {
    std::fs::symlink_metadata(p).unwrap().file_type()
}

#[test]
fn export_never_writes_over_its_input_or_one_output_over_another() {
    let dir = common::scratch_dir("export-clobber");
    let src = dir.join("src.mcap");
    record_rollout(&src, 1, 3, false);
    let original = std::fs::read(&src).unwrap();
    std::fs::hard_link(&src, dir.join("hard.h5")).unwrap();
    std::os::unix::fs::symlink(&src, dir.join("soft.h5")).unwrap();
    std::fs::create_dir(dir.join("sub")).unwrap();
    std::fs::write(dir.join("t3b.h5"), b"old t3b").unwrap();
    std::fs::write(dir.join("same.json"), b"old same").unwrap();
    let before = listing(&dir);
    let export = |args: &[&str]| {
        let mut c = mjskill();
        c.current_dir(&dir)
            .args(["export", "src.mcap", "--format", "maniskill"])
            .args(args);
        c
    };
    // The output is the recording: by its name, through `..`, a hard link, a symbolic link.
    for o in ["src.mcap", "sub/../src.mcap", "hard.h5", "soft.h5"] {
        let err = fails(&mut export(&["-o", o]));
        assert!(
            err.contains(&format!("-o {o} is the recording src.mcap"))
                && err.contains("nothing was written"),
            "{err}"
        );
    }
    let err = fails(&mut export(&["-o", "t2.h5", "--json", "src.mcap"]));
    assert!(
        err.contains("--json src.mcap is the recording src.mcap"),
        "{err}"
    );
    // The h5 and the json at one path, named or by the default json name.
    let err = fails(&mut export(&["-o", "t3b.h5", "--json", "t3b.h5"]));
    assert!(
        err.contains("-o t3b.h5 and --json t3b.h5 are the same file"),
        "{err}"
    );
    let err = fails(&mut export(&["-o", "same.json"]));
    assert!(
        err.contains("-o same.json and the json (default: -o with extension .json) same.json"),
        "{err}"
    );
    let err = fails(&mut export(&["-o", "new.json"]));
    assert!(err.contains("are the same file"), "{err}");
    assert_eq!(std::fs::read(&src).unwrap(), original);
    assert_eq!(std::fs::read(dir.join("t3b.h5")).unwrap(), b"old t3b");
    assert_eq!(std::fs::read(dir.join("same.json")).unwrap(), b"old same");
    assert_eq!(listing(&dir), before);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn export_refuses_non_regular_outputs_and_a_failed_export_leaves_nothing() {
    let dir = common::scratch_dir("export-special");
    let src = dir.join("src.mcap");
    record_rollout(&src, 1, 3, false);
    let fifo = dir.join("fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    std::fs::create_dir(dir.join("d")).unwrap();
    // A link to /dev/full rather than /dev/full itself: an export that renamed over it
    // replaces the link, never the device (the test may run as root).
    let full = dir.join("full");
    std::os::unix::fs::symlink("/dev/full", &full).unwrap();
    let before = listing(&dir);
    let export = |args: &[&str]| {
        let mut c = mjskill();
        c.current_dir(&dir)
            .args(["export", "src.mcap", "--format", "maniskill"])
            .args(args);
        c
    };
    // A device or a FIFO is neither replaced by a rename nor reported as written.
    let err = fails(&mut export(&["-o", "full", "--json", "x.json"]));
    assert!(
        err.contains("-o full is a character device, not a regular file"),
        "{err}"
    );
    assert!(file_type(&full).is_symlink());
    {
        use std::os::unix::fs::FileTypeExt;
        let err = fails(&mut export(&["-o", "t.h5", "--json", "fifo"]));
        assert!(err.contains("--json fifo is a FIFO"), "{err}");
        assert!(file_type(&fifo).is_fifo());
    }
    // --json naming a directory: refused before the h5 is written.
    let err = fails(&mut export(&["-o", "t.h5", "--json", "d"]));
    assert!(err.contains("--json d is a directory"), "{err}");
    let err = fails(&mut export(&["-o", "nodir/t.h5"]));
    assert!(err.contains("the directory nodir does not exist"), "{err}");
    assert_eq!(listing(&dir), before);
    // The same through the library: nothing is left behind either.
    let e = export::to_maniskill(&src, &dir.join("t.h5"), Some(&dir.join("d")))
        .unwrap_err()
        .to_string();
    assert!(e.contains("is a directory"), "{e}");
    assert_eq!(listing(&dir), before);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A copy of the PickCube demos (`v.h5`, `v.json`) in `dir`.
fn demo_copy(dir: &Path) -> (PathBuf, PathBuf) {
    let src = demos().join("PickCube-v1");
    let (h5, json) = (dir.join("v.h5"), dir.join("v.json"));
    std::fs::copy(src.join("trajectory.h5"), &h5).unwrap();
    std::fs::copy(src.join("trajectory.json"), &json).unwrap();
    (h5, json)
}

#[test]
fn import_never_writes_over_its_input() {
    let dir = common::scratch_dir("import-clobber");
    let (h5, json) = demo_copy(&dir);
    let (h5_bytes, json_bytes) = (std::fs::read(&h5).unwrap(), std::fs::read(&json).unwrap());
    for (out, named) in [
        ("v.h5", "the h5 v.h5"),
        (
            "v.json",
            "the json (default: the h5 with extension .json) v.json",
        ),
    ] {
        let err =
            fails(
                mjskill()
                    .current_dir(&dir)
                    .args(["import-maniskill", "v.h5", "--out", out]),
            );
        assert!(err.contains(&format!("--out {out} is {named}")), "{err}");
    }
    let err = fails(mjskill().current_dir(&dir).args([
        "import-maniskill",
        "v.h5",
        "--json",
        "v.json",
        "--out",
        "./v.json",
    ]));
    assert!(err.contains("--out ./v.json is --json v.json"), "{err}");
    // A link to /dev/full (never the device itself: see the export test).
    std::os::unix::fs::symlink("/dev/full", dir.join("full")).unwrap();
    let err =
        fails(
            mjskill()
                .current_dir(&dir)
                .args(["import-maniskill", "v.h5", "--out", "full"]),
        );
    assert!(err.contains("--out full is a character device"), "{err}");
    assert!(file_type(&dir.join("full")).is_symlink());
    assert_eq!(std::fs::read(&h5).unwrap(), h5_bytes);
    assert_eq!(std::fs::read(&json).unwrap(), json_bytes);
    assert_eq!(listing(&dir), ["full", "v.h5", "v.json"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Replaces `traj_0/actions` of `h5` by a chunked dataset of `shape` that holds no data (it
/// reads as zeros): a few KB on disk, `shape` in memory.
fn declare_actions(h5: &Path, shape: (usize, usize)) {
    let f = hdf5_metno::File::open_rw(h5).unwrap();
    let g = f.group("traj_0").unwrap();
    g.unlink("actions").unwrap();
    g.new_dataset::<f32>()
        .chunk((shape.0.min(1 << 16), shape.1.min(8)))
        .shape(shape)
        .create("actions")
        .unwrap();
    f.close().unwrap();
}

#[test]
fn import_checks_declared_shapes_before_reading() {
    let dir = common::scratch_dir("import-shapes");
    let (h5, json) = demo_copy(&dir);
    declare_actions(&h5, (2_000_000_000, 8));
    assert!(std::fs::metadata(&h5).unwrap().len() < 1 << 20);
    let import = || {
        let mut c = mjskill();
        c.current_dir(&dir)
            .args(["import-maniskill", "v.h5", "--out", "o.mcap"]);
        c
    };
    let err = fails(&mut import());
    assert!(
        err.contains("traj_0/actions declares 2000000000 rows, expected 82")
            && err.contains("elapsed_steps"),
        "{err}"
    );
    // A json that agrees with the declared shape is refused by the step limit.
    let text = std::fs::read_to_string(&json).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["episodes"][0]["elapsed_steps"] = 2_000_000_000u32.into();
    std::fs::write(&json, v.to_string()).unwrap();
    let err = fails(&mut import());
    assert!(
        err.contains("episode 0: elapsed_steps 2000000000 exceeds the limit of 100000"),
        "{err}"
    );
    // Too many columns.
    std::fs::write(&json, &text).unwrap();
    declare_actions(&h5, (82, 1 << 20));
    let err = fails(&mut import());
    assert!(
        err.contains("traj_0/actions declares 1048576 columns, beyond the limit of 4096"),
        "{err}"
    );
    assert_eq!(listing(&dir), ["v.h5", "v.json"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An edit of a trajectory json.
type JsonEdit = Box<dyn Fn(&mut serde_json::Value)>;

#[test]
fn import_rejects_a_json_that_disagrees_with_itself_or_the_h5() {
    let dir = common::scratch_dir("import-json");
    let (_, json) = demo_copy(&dir);
    let text = std::fs::read_to_string(&json).unwrap();
    let base: serde_json::Value = serde_json::from_str(&text).unwrap();
    let cases: Vec<(&str, JsonEdit, &str)> = vec![
        (
            "repeated episode id",
            Box::new(|v| v["episodes"][1]["episode_id"] = 0.into()),
            "episodes[0] and episodes[1] both have episode_id 0",
        ),
        (
            "seed 2^32",
            Box::new(|v| {
                v["episodes"][0]["episode_seed"] = (1u64 << 32).into();
                v["episodes"][0]["reset_kwargs"]["seed"] = (1u64 << 32).into();
            }),
            "episode 0: reset_kwargs.seed 4294967296 is not an integer in 0..=4294967295",
        ),
        (
            "null seeds",
            Box::new(|v| {
                v["episodes"][1]["episode_seed"] = serde_json::Value::Null;
                v["episodes"][1]["reset_kwargs"]["seed"] = serde_json::Value::Null;
            }),
            "episode 1: no seed",
        ),
        (
            "seeds that disagree",
            Box::new(|v| v["episodes"][2]["episode_seed"] = 7.into()),
            "episode 2: reset_kwargs.seed 1302 and episode_seed 7 differ",
        ),
        (
            "elapsed_steps",
            Box::new(|v| v["episodes"][1]["elapsed_steps"] = 91.into()),
            "traj_1/actions declares 92 rows, expected 91 (episode 1's elapsed_steps",
        ),
        (
            "unknown robot",
            Box::new(|v| v["env_info"]["env_kwargs"]["robot_uids"] = "ur5".into()),
            "env_info.env_kwargs.robot_uids \"ur5\" is not a robot of PickCube-v1; valid: panda",
        ),
        (
            "another robot",
            Box::new(|v| v["env_info"]["env_kwargs"]["robot_uids"] = "fetch".into()),
            "robot_uids is \"fetch\" but the h5's episodes hold the robot \"panda\"",
        ),
    ];
    for (what, edit, expected) in cases {
        let mut v = base.clone();
        edit(&mut v);
        std::fs::write(&json, v.to_string()).unwrap();
        let err = fails(mjskill().current_dir(&dir).args([
            "import-maniskill",
            "v.h5",
            "--out",
            "o.mcap",
        ]));
        assert!(err.contains(expected), "{what}: {err}");
        assert_eq!(listing(&dir), ["v.h5", "v.json"], "{what}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn import_by_states_names_a_row_with_a_zero_quaternion() {
    let dir = common::scratch_dir("import-quat");
    let (h5, _) = demo_copy(&dir);
    {
        let f = hdf5_metno::File::open_rw(&h5).unwrap();
        let ds = f.dataset("traj_0/env_states/actors/cube").unwrap();
        let mut v = ds.read_raw::<f32>().unwrap();
        v[5 * 13 + 3..5 * 13 + 7].fill(0.0);
        ds.write_raw(&v).unwrap();
        f.close().unwrap();
    }
    for by in ["states", "actions"] {
        let err = fails(mjskill().current_dir(&dir).args([
            "import-maniskill",
            "v.h5",
            "--by",
            by,
            "--out",
            "o.mcap",
        ]));
        assert!(
            err.contains(
                "traj_0/env_states/actors/cube row 5: the pose quaternion (w, x, y, z) \
                 [0.0, 0.0, 0.0, 0.0] has norm 0"
            ),
            "{err}"
        );
    }
    assert_eq!(listing(&dir), ["v.h5", "v.json"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Recomputes a LeRobot v3 dataset's statistics with numpy from its parquet rows and its
/// decoded videos (PyAV), independently of mjskill: prints the largest deviations of
/// `meta/stats.json` and of the per-episode `stats/<feature>/<stat>` columns, and of the
/// per-episode stats aggregated as LeRobot's `aggregate_stats` does.
const STATS_CHECK: &str = r#"
import json, sys, pathlib
import numpy as np, pyarrow.parquet as pq, av
root = pathlib.Path(sys.argv[1])
info = json.loads((root / "meta/info.json").read_text())
stats = json.loads((root / "meta/stats.json").read_text())
data = pq.read_table(root / "data/chunk-000/file-000.parquet").to_pydict()
eps = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
Q = {"q01": 0.01, "q10": 0.10, "q50": 0.50, "q90": 0.90, "q99": 0.99}
NAMES = ["min", "max", "mean", "std", "count"] + list(Q)
def numpy_stats(a, axes):
    s = {"min": a.min(axis=axes), "max": a.max(axis=axes), "mean": a.mean(axis=axes),
         "std": a.std(axis=axes), "count": np.array([a.shape[0]])}
    for k, q in Q.items():
        s[k] = np.quantile(a, q, axis=axes)
    return s
out = {"missing": [], "dev_total": 0.0, "dev_episode": 0.0, "dev_aggregate": 0.0,
       "dev_video": 0.0, "shapes": {}, "counts": {}}
def dev(key, a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.size != b.size:
        out["missing"].append(f"{key}: size {a.size} vs {b.size}")
        return 0.0
    return float(np.abs(a.ravel() - b.ravel()).max())
frames = {}
for key, ft in info["features"].items():
    if ft["dtype"] == "video":
        path = root / info["video_path"].format(video_key=key, chunk_index=0, file_index=0)
        with av.open(str(path)) as c:
            imgs = [f.to_ndarray(format="rgb24") for f in c.decode(c.streams.video[0])]
        frames[key] = np.stack(imgs).astype(np.float64) / 255.0
for key, ft in info["features"].items():
    video = ft["dtype"] == "video"
    if video:
        allrows, axes = frames[key], (0, 1, 2)
    else:
        allrows = np.array(data[key], dtype=np.float64)
        allrows, axes = allrows.reshape(len(allrows), -1), 0
    want = numpy_stats(allrows, axes)
    for n in NAMES:
        if n not in stats.get(key, {}):
            out["missing"].append(f"stats.json {key}/{n}")
            continue
        got = np.asarray(stats[key][n], dtype=float)
        if video and n != "count":
            out["shapes"][key] = list(got.shape)
        d = dev(f"{key}/{n}", got, want[n])
        if n == "count":
            out["counts"][key] = int(got[0])
        elif video:
            out["dev_video"] = max(out["dev_video"], d)
        else:
            out["dev_total"] = max(out["dev_total"], d)
    per = []
    for e in eps:
        a, b = e["dataset_from_index"], e["dataset_to_index"]
        w = numpy_stats(allrows[a:b], axes)
        s = {}
        for n in NAMES:
            col = f"stats/{key}/{n}"
            if col not in e:
                out["missing"].append(col)
                continue
            s[n] = np.asarray(e[col], dtype=float)
            if video and n != "count":
                out["shapes"]["episode " + key] = list(s[n].shape)
            d = dev(col, s[n], w[n])
            out["dev_video" if video and n != "count" else "dev_episode"] = max(
                out["dev_video" if video and n != "count" else "dev_episode"], d)
        per.append(s)
    if per and all(len(s) == len(NAMES) for s in per):
        # LeRobot's aggregate_stats: weighted means, pooled variances, min of mins, max of maxes.
        counts = np.array([s["count"][0] for s in per], dtype=float)
        means = np.stack([s["mean"] for s in per])
        c = counts.reshape((-1,) + (1,) * (means.ndim - 1))
        mean = (means * c).sum(0) / counts.sum()
        var = ((np.stack([s["std"] for s in per]) ** 2 + (means - mean) ** 2) * c).sum(0) / counts.sum()
        agg = {"min": np.stack([s["min"] for s in per]).min(0), "max": np.stack([s["max"] for s in per]).max(0),
               "mean": mean, "std": np.sqrt(var)}
        for n, v in agg.items():
            out["dev_aggregate"] = max(out["dev_aggregate"], dev(f"aggregate {key}/{n}", v, stats[key][n]))
print(json.dumps(out))
"#;

#[test]
fn lerobot_stats_hold_quantiles_and_per_episode_columns() {
    let dir = common::scratch_dir("lerobot-stats");
    let mcap = dir.join("run.mcap");
    record_rollout(&mcap, 2, 4, true);
    let ds = dir.join("ds");
    mjskill::datasets::lerobot::write(&mcap, &ds, Some(true)).unwrap();
    let Some(py) = python() else { return };
    let o = Command::new(py)
        .arg("-c")
        .arg(STATS_CHECK)
        .arg(&ds)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["missing"], serde_json::json!([]), "{v}");
    // Float32 data: the quantiles and moments agree with numpy's to rounding.
    for k in ["dev_total", "dev_episode", "dev_aggregate"] {
        assert!(v[k].as_f64().unwrap() < 1e-6, "{k}: {v}");
    }
    // Video statistics from mjskill's decoder against FFmpeg's (colour conversion rounding).
    assert!(v["dev_video"].as_f64().unwrap() < 0.02, "{v}");
    let cam = "observation.images.render_camera";
    assert_eq!(v["shapes"][cam], serde_json::json!([3, 1, 1]));
    assert_eq!(
        v["shapes"][format!("episode {cam}")],
        serde_json::json!([3, 1, 1])
    );
    assert_eq!(v["counts"]["action"], 8);
    assert_eq!(v["counts"][cam], 8);
    std::fs::remove_dir_all(&dir).unwrap();
}

fn mjskill_cli(args: &[&str], paths: &[&Path]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
        .args(args)
        .args(paths)
        .output()
        .unwrap()
}

/// `export --control-mode pd_joint_pos` writes the joint targets mjskill's controller set
/// (Fetch's EE solver: the IK solution), so the episode replays in `pd_joint_pos` (which
/// ManiSkill can build for Fetch) with the same outcome and objects.
#[test]
fn export_converts_fetch_ee_actions_to_joint_targets_that_replay_the_episode() {
    let dir = common::scratch_dir("convert");
    let mcap = dir.join("fetch.mcap");
    let o = mjskill_cli(
        &[
            "rollout",
            "--env",
            "PickCube-v1",
            "--robot",
            "fetch",
            "--episodes",
            "2",
            "--seed",
            "3",
            "--no-frame",
            "--out",
        ],
        &[&mcap],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rec = record::read(&mcap).unwrap();
    assert_eq!(rec.meta.control_mode, "pd_ee_delta_pose");
    let h5 = dir.join("fetch.h5");
    let o = mjskill_cli(
        &[
            "export",
            "--format",
            "maniskill",
            "--control-mode",
            "pd_joint_pos",
            "-o",
        ],
        &[&h5, &mcap],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t = maniskill_h5::read(&h5, None).unwrap();
    assert_eq!(t.json.env_info.env_kwargs["control_mode"], "pd_joint_pos");
    for (info, (ep, rec_ep)) in t
        .json
        .episodes
        .iter()
        .zip(t.episodes.iter().zip(rec.finished()))
    {
        assert_eq!(info.control_mode, "pd_joint_pos");
        // arm 7 joint targets, gripper, body 3, base 2.
        assert_eq!(ep.action_dim, 13);
        assert_eq!(ep.steps(), rec_ep.steps.len());
        for (t, s) in rec_ep.steps.iter().enumerate() {
            // The gripper, body and base parts are the recorded ones.
            assert_eq!(ep.action(t)[7..], s.action[6..], "step {t}");
        }
    }
    // Replayed in mjskill by actions: the recorded outcome, objects within 0.1 mm.
    let r = import(&h5, None, &dir.join("back.mcap"), ReplayBy::Actions).unwrap();
    assert_eq!(r.control_mode, "pd_joint_pos");
    for (e, rec_ep) in r.episodes.iter().zip(rec.finished()) {
        assert_eq!(e.by_actions_success, rec_ep.success, "seed {:?}", e.seed);
        assert_eq!(e.maniskill_success, rec_ep.success);
        assert!(e.max_object_error_m < 1e-4, "{e:?}");
    }
    // The recording's own mode exports as recorded; other modes are errors naming the valid
    // ones; LeRobot takes no control mode.
    let same = dir.join("same.h5");
    let o = mjskill_cli(
        &[
            "export",
            "--format",
            "maniskill",
            "--control-mode",
            "pd_ee_delta_pose",
            "-o",
        ],
        &[&same, &mcap],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        maniskill_h5::read(&same, None).unwrap().episodes[0].action_dim,
        12
    );
    let o = mjskill_cli(
        &[
            "export",
            "--format",
            "maniskill",
            "--control-mode",
            "pd_joint_vel",
            "-o",
        ],
        &[&dir.join("bad.h5"), &mcap],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success()
            && err.contains("\"pd_joint_vel\"")
            && err.contains("valid: pd_joint_pos, pd_ee_delta_pose"),
        "{err}"
    );
    assert!(!dir.join("bad.h5").exists());
    let o = mjskill_cli(
        &[
            "export",
            "--format",
            "lerobot",
            "--control-mode",
            "pd_joint_pos",
            "-o",
        ],
        &[&dir.join("lr"), &mcap],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--format maniskill only"),
        "{err}"
    );
    // A mode that accumulates targets cannot be converted.
    let tgt = dir.join("target.mcap");
    let o = mjskill_cli(
        &[
            "rollout",
            "--policy",
            "zero",
            "--episodes",
            "1",
            "--no-frame",
            "--control-mode",
            "pd_joint_target_delta_pos",
            "--out",
        ],
        &[&tgt],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = mjskill_cli(
        &[
            "export",
            "--format",
            "maniskill",
            "--control-mode",
            "pd_joint_pos",
            "-o",
        ],
        &[&dir.join("t.h5"), &tgt],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("accumulates targets"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Compares a split LeRobot export (argv[2]) with the single-file export of the same
/// recording (argv[1]): every episode's indices point at the files holding its rows and
/// frames, every row is present exactly once, the video timestamps match the frames, and the
/// files' contents concatenated equal the single files'. Prints JSON: problems and counts.
const SPLIT_CHECK: &str = r#"
import json, sys, pathlib
import pyarrow as pa, pyarrow.parquet as pq, av
one, split = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
info = json.loads((split / "meta/info.json").read_text())
bad = []
def files(root, pattern):
    return sorted(root.glob(pattern))
def chunk_file(p):
    return int(p.parent.name.split("-")[1]), int(p.stem.split("-")[1])
cs = info["chunks_size"]
out = {"info": {k: info[k] for k in ["chunks_size", "data_files_size_in_mb", "video_files_size_in_mb"]}}
# Files are numbered densely: chunk c holds files 0..cs-1 before chunk c+1 starts.
def dense(paths, what):
    got = [chunk_file(p) for p in paths]
    want = [(i // cs, i % cs) for i in range(len(paths))]
    if got != want:
        bad.append(f"{what} files {got} are not numbered {want}")
# meta/episodes: each row in the file it names.
eps = []
meta_files = files(split, "meta/episodes/chunk-*/file-*.parquet")
dense(meta_files, "meta/episodes")
for p in meta_files:
    for r in pq.read_table(p).to_pylist():
        if (r["meta/episodes/chunk_index"], r["meta/episodes/file_index"]) != chunk_file(p):
            bad.append(f"episode {r['episode_index']} in {p} names another meta file")
        eps.append(r)
one_eps = pq.read_table(one / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
skip = lambda r: {k: v for k, v in r.items() if not k.endswith(("chunk_index", "file_index", "_timestamp"))}
if [skip(r) for r in eps] != [skip(r) for r in one_eps]:
    bad.append("meta/episodes rows differ from the single-file export's")
# Data: each episode's rows in the file it names, at its dataset indices; every row once.
data_files = files(split, "data/chunk-*/file-*.parquet")
dense(data_files, "data")
tables = {chunk_file(p): pq.read_table(p) for p in data_files}
for r in eps:
    t = tables.get((r["data/chunk_index"], r["data/file_index"]))
    if t is None:
        bad.append(f"episode {r['episode_index']} names a missing data file"); continue
    idx = [i for i, e in zip(t.column("index").to_pylist(), t.column("episode_index").to_pylist()) if e == r["episode_index"]]
    if idx != list(range(r["dataset_from_index"], r["dataset_to_index"])) or len(idx) != r["length"]:
        bad.append(f"episode {r['episode_index']}: rows {idx[:3]}... not at {r['dataset_from_index']}..{r['dataset_to_index']}")
split_data = pa.concat_tables([tables[chunk_file(p)] for p in data_files])
one_data = pq.read_table(one / "data/chunk-000/file-000.parquet")
if split_data.column("index").to_pylist() != list(range(info["total_frames"])):
    bad.append("the data files' rows are not every index exactly once")
if not split_data.equals(one_data):
    bad.append("the data files' rows differ from the single-file export's")
out["data_files"] = len(data_files)
out["meta_files"] = len(meta_files)
out["data_chunks"] = len({chunk_file(p)[0] for p in data_files})
out["max_episodes_per_data_file"] = max(len(set(t.column("episode_index").to_pylist())) for t in tables.values())
# Videos: the frames of each episode sit in [from_timestamp, to_timestamp) of its file and
# decode to the single-file video's pictures.
def decode(path):
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        return [(round(float(f.pts * s.time_base), 6), f.to_ndarray(format="rgb24").tobytes()) for f in c.decode(s)]
out["video_files"] = {}
for key, ft in info["features"].items():
    if ft["dtype"] != "video":
        continue
    vfiles = files(split, f"videos/{key}/chunk-*/file-*.mp4")
    dense(vfiles, key)
    decoded = {chunk_file(p): decode(p) for p in vfiles}
    single = decode(one / f"videos/{key}/chunk-000/file-000.mp4")
    got = []
    for r in eps:
        frames = decoded.get((r[f"videos/{key}/chunk_index"], r[f"videos/{key}/file_index"]))
        if frames is None:
            bad.append(f"episode {r['episode_index']} names a missing {key} file"); continue
        lo, hi = r[f"videos/{key}/from_timestamp"], r[f"videos/{key}/to_timestamp"]
        mine = [px for ts, px in frames if lo - 1e-6 <= ts < hi - 1e-6]
        if len(mine) != r["length"] or abs(hi - lo - r["length"] / info["fps"]) > 1e-9:
            bad.append(f"episode {r['episode_index']}: {len(mine)} {key} frames in [{lo}, {hi}), length {r['length']}")
        got.extend(mine)
    if sum(len(f) for f in decoded.values()) != len(single):
        bad.append(f"{key}: the files hold {sum(len(f) for f in decoded.values())} frames, expected {len(single)}")
    if got != [px for _, px in single]:
        bad.append(f"{key}: the episodes' frames differ from the single-file video's")
    out["video_files"][key] = len(vfiles)
out["bad"] = bad
print(json.dumps(out))
"#;

#[test]
fn lerobot_export_splits_files_and_chunks_by_size_as_lerobot() {
    use mjskill::datasets::lerobot::{self, Limits};
    let dir = common::scratch_dir("lerobot-split");
    let mcap = dir.join("run.mcap");
    record_rollout(&mcap, 5, 6, true);
    let one = dir.join("one");
    lerobot::write(&mcap, &one, Some(true)).unwrap();
    // LeRobot's defaults in info.json; a small export fits one file of each kind.
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(one.join("meta/info.json")).unwrap()).unwrap();
    assert_eq!(info["chunks_size"], 1000);
    assert_eq!(info["data_files_size_in_mb"], 100);
    assert_eq!(info["video_files_size_in_mb"], 200);
    assert_eq!(listing(&one.join("data")), ["chunk-000"]);
    assert_eq!(listing(&one.join("data/chunk-000")), ["file-000.parquet"]);
    let size_mb = |p: &Path| std::fs::metadata(p).unwrap().len() as f64 / (1024.0 * 1024.0);
    // The data limit applies to the row groups written so far (LeRobot measures a file its
    // ParquetWriter still holds open, so the footer is not counted): the footer's length is
    // the 4 bytes before the closing "PAR1".
    let data_mb = {
        let bytes = std::fs::read(one.join("data/chunk-000/file-000.parquet")).unwrap();
        let n = bytes.len();
        assert_eq!(&bytes[n - 4..], b"PAR1");
        let footer = u32::from_le_bytes(bytes[n - 8..n - 4].try_into().unwrap()) as usize;
        (n - 8 - footer) as f64 / (1024.0 * 1024.0)
    };
    let video_mb =
        size_mb(&one.join("videos/observation.images.render_camera/chunk-000/file-000.mp4"));

    // Limits of half the single files: 2 to 4 files of 1 to 3 episodes each, one file per
    // chunk. Tiny limits: one episode per file (episodes are never split).
    let cases = [
        (1, data_mb * 0.5, video_mb * 0.5, false),
        (2, 1e-6, 1e-6, true),
        (1, 1e-6, 1e-6, true),
    ];
    for (i, (chunks_size, data, video, one_each)) in cases.into_iter().enumerate() {
        let limits = Limits {
            chunks_size,
            data_files_size_in_mb: data,
            video_files_size_in_mb: video,
        };
        let ds = dir.join(format!("split{i}"));
        let s = lerobot::write_with_limits(&mcap, &ds, Some(true), &limits).unwrap();
        assert_eq!((s.episodes, s.steps), (5, 30));
        let info: serde_json::Value =
            serde_json::from_slice(&std::fs::read(ds.join("meta/info.json")).unwrap()).unwrap();
        assert_eq!(info["chunks_size"], chunks_size);
        assert_eq!(info["data_files_size_in_mb"], data);
        // Files under a directory of chunk folders.
        let count = |sub: &str| -> usize {
            std::fs::read_dir(ds.join(sub))
                .unwrap()
                .map(|c| std::fs::read_dir(c.unwrap().path()).unwrap().count())
                .sum()
        };
        let video_files = count("videos/observation.images.render_camera");
        let data_files = count("data");
        if one_each {
            assert_eq!((data_files, video_files, count("meta/episodes")), (5, 5, 5));
            assert!(ds
                .join(format!("data/chunk-00{}/file-000.parquet", 4 / chunks_size))
                .is_file());
        } else {
            assert!((2..5).contains(&data_files), "{data_files} data files");
            assert!((2..5).contains(&video_files), "{video_files} video files");
            assert!(ds.join("data/chunk-001/file-000.parquet").is_file());
        }
        let Some(py) = python() else { continue };
        let o = Command::new(&py)
            .arg("-c")
            .arg(SPLIT_CHECK)
            .arg(&one)
            .arg(&ds)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["bad"], serde_json::json!([]), "case {i}: {v}");
        assert_eq!(v["data_files"], data_files, "{v}");
        if !one_each {
            assert!(
                v["max_episodes_per_data_file"].as_u64().unwrap() >= 2,
                "{v}"
            );
        }
    }

    // Bad limits are refused with the value and the valid range; nothing is written.
    for (limits, needle) in [
        (
            Limits {
                chunks_size: 0,
                ..Limits::default()
            },
            "chunks_size 0",
        ),
        (
            Limits {
                video_files_size_in_mb: -1.0,
                ..Limits::default()
            },
            "video_files_size_in_mb -1",
        ),
    ] {
        let ds = dir.join("bad");
        let e = lerobot::write_with_limits(&mcap, &ds, Some(true), &limits)
            .unwrap_err()
            .to_string();
        assert!(e.contains(needle) && e.contains("valid"), "{e}");
        assert!(!ds.exists());
    }

    // The CLI flags.
    let ds = dir.join("cli");
    let o = mjskill()
        .args(["export", "--format", "lerobot", "--chunks-size", "3"])
        .args([
            "--data-files-size-in-mb",
            "0.000001",
            "--video-files-size-in-mb",
            "0.000001",
        ])
        .arg(&mcap)
        .arg("-o")
        .arg(&ds)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(ds.join("data/chunk-001/file-001.parquet").is_file());
    assert!(ds
        .join("videos/observation.images.render_camera/chunk-001/file-001.mp4")
        .is_file());
    let e = fails(
        mjskill()
            .args(["export", "--format", "maniskill", "--chunks-size", "3"])
            .arg(&mcap),
    );
    assert!(e.contains("--format lerobot only"), "{e}");
}

/// A child process started by another thread while an h5 file is being written inherits the
/// writer's file descriptor (HDF5 opens without `O_CLOEXEC`). With HDF5's file locking that
/// child would hold the writer's exclusive lock after the writer closed the file, and reading
/// the finished file failed with "unable to lock file, errno = 11" (seen in CI). The writer
/// therefore takes no lock: its file has a private temporary name until it is complete.
#[test]
fn h5_written_while_other_threads_start_processes_reads_back_at_once() {
    let dir = common::scratch_dir("h5-children");
    let mcap = dir.join("demo.mcap");
    import(
        &demos().join("PokeCube-v1/trajectory.h5"),
        None,
        &mcap,
        ReplayBy::States,
    )
    .unwrap();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let spawner = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let mut children = Vec::new();
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                children.push(Command::new("sleep").arg("3").spawn().unwrap());
                std::thread::sleep(std::time::Duration::from_millis(2));
                if children.len() > 200 {
                    for mut c in children.drain(..100) {
                        let _ = c.kill();
                        let _ = c.wait();
                    }
                }
            }
            for mut c in children {
                let _ = c.kill();
                let _ = c.wait();
            }
        })
    };
    let mut failures = Vec::new();
    for k in 0..20 {
        let out = dir.join(format!("traj{k}.h5"));
        export::to_maniskill(&mcap, &out, None).unwrap();
        if let Err(e) = maniskill_h5::read(&out, None) {
            failures.push(format!("{k}: {e}"));
        }
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    spawner.join().unwrap();
    assert!(failures.is_empty(), "{failures:#?}");
}
