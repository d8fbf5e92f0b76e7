//! MCAP episode recording: round trip, exact replay from recorded states, durability of
//! finished episodes when the recorder is killed, damaged and foreign files.

mod common;
use std::path::Path;

use mjskill::record::{self, RecordError, Recorder};
use mjskill::{make, Env, EnvConfig};

fn env() -> Env {
    make("PickCube-v1", EnvConfig::default()).unwrap()
}

/// A deterministic, varied action.
fn action(dim: usize, ep: usize, t: usize) -> Vec<f32> {
    (0..dim)
        .map(|i| (((i * 7 + t * 3 + ep * 5) % 11) as f32 / 5.0 - 1.0) * 0.8)
        .collect()
}

/// What the env returned for one step.
#[derive(Debug, Clone)]
struct Seen {
    obs: Vec<f32>,
    reward: f32,
    terminated: bool,
    truncated: bool,
}

/// Records `episodes` episodes of `steps` steps (seeds 10, 11, ...) and returns what the env
/// returned: (seed, initial obs, steps) per episode. `finish` false leaves the recorder to
/// the caller.
fn record_episodes(
    rec: &mut Recorder,
    env: &mut Env,
    first: usize,
    episodes: usize,
    steps: usize,
    end: bool,
) -> Vec<(u64, Vec<f32>, Vec<Seen>)> {
    let dim = env.action_space().shape[0];
    let mut out = Vec::new();
    for ep in first..first + episodes {
        let seed = 10 + ep as u64;
        let (obs0, _) = env.reset(Some(seed));
        let obs0 = obs0.to_vec();
        rec.begin_episode(env, Some(seed)).unwrap();
        let mut seen = Vec::new();
        for t in 0..steps {
            let a = action(dim, ep, t);
            let before = env.get_state();
            let s = env.step(&a).unwrap();
            let v = Seen {
                obs: s.obs.to_vec(),
                reward: s.reward,
                terminated: s.terminated,
                truncated: s.truncated,
            };
            rec.record_step(env, &a, v.reward, v.terminated, v.truncated, &before)
                .unwrap();
            seen.push(v);
        }
        if end {
            let success = env.info().success();
            rec.end_episode(success).unwrap();
        }
        out.push((seed, obs0, seen));
    }
    out
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn round_trip_and_exact_replay() {
    let path = common::scratch("roundtrip.mcap");
    let mut env = env();
    let mut rec = Recorder::create(&path, &env).unwrap();
    let seen = record_episodes(&mut rec, &mut env, 0, 2, 6, true);
    rec.finish().unwrap();

    let r = record::read(&path).unwrap();
    assert!(r.complete);
    let m = &r.meta;
    assert_eq!(m.env_id, "PickCube-v1");
    assert_eq!(m.robot, env.robot_id().uid());
    assert_eq!(m.obs_mode, env.config().obs_mode.name());
    assert_eq!(m.reward_mode, env.config().reward_mode.name());
    assert_eq!(m.control_mode, env.get_state().control_mode);
    assert_eq!(m.max_episode_steps, env.max_episode_steps());
    assert_eq!(m.timestep, env.model().timestep());
    assert_eq!(m.substeps, env.substeps());
    assert_eq!(m.sim(), env.config().sim);
    assert_eq!(m.version, env!("CARGO_PKG_VERSION"));
    assert_eq!(m.action_space.shape, env.action_space().shape);
    assert_eq!(bits(&m.action_space.low), bits(&env.action_space().low));
    assert_eq!(bits(&m.action_space.high), bits(&env.action_space().high));
    assert_eq!(m.observation_space.shape, env.observation_space().shape);
    assert_eq!(
        bits(&m.observation_space.high),
        bits(&env.observation_space().high)
    );
    let layout: Vec<(String, usize, usize)> = env
        .obs_layout()
        .iter()
        .map(|(k, r)| (k.clone(), r.start, r.end))
        .collect();
    let got: Vec<(String, usize, usize)> = m
        .obs_layout
        .iter()
        .map(|s| (s.name.clone(), s.start, s.end))
        .collect();
    assert_eq!(got, layout);

    assert_eq!(r.episodes.len(), 2);
    for (k, (ep, (seed, obs0, steps))) in r.episodes.iter().zip(&seen).enumerate() {
        assert_eq!(ep.index, k as u64);
        assert_eq!(ep.seed, Some(*seed));
        assert!(ep.finished);
        assert_eq!(bits(&ep.initial_obs), bits(obs0));
        assert_eq!(ep.initial_info[0].0, "elapsed_steps");
        assert_eq!(ep.steps.len(), steps.len());
        let mut ret = 0.0f64;
        for (t, (s, want)) in ep.steps.iter().zip(steps).enumerate() {
            assert_eq!(bits(&s.obs), bits(&want.obs), "ep {k} step {t} obs");
            assert_eq!(s.reward.to_bits(), want.reward.to_bits(), "ep {k} step {t}");
            assert_eq!(s.terminated, want.terminated);
            assert_eq!(s.truncated, want.truncated);
            assert_eq!(s.state.elapsed_steps, t as u32);
            assert_eq!(s.info[0], ("elapsed_steps".to_string(), (t + 1) as f64));
            let keys: Vec<&str> = s.info[1..].iter().map(|(k, _)| k.as_str()).collect();
            assert_eq!(keys, env.info().keys);
            ret += s.reward as f64;
        }
        assert_eq!(ep.ret, ret);
    }

    // Restore any recorded state and replay: bitwise the same trajectory.
    let mut fresh = make("PickCube-v1", EnvConfig::default()).unwrap();
    for ep in &r.episodes {
        fresh.set_state(&ep.initial_state).unwrap();
        assert_eq!(bits(fresh.obs()), bits(&ep.initial_obs));
        assert_eq!(fresh.get_state(), ep.steps[0].state);
        for (t, s) in ep.steps.iter().enumerate().rev() {
            fresh.set_state(&s.state).unwrap();
            let got = fresh.step(&s.action).unwrap();
            assert_eq!(bits(got.obs), bits(&s.obs), "episode {} step {t}", ep.index);
            assert_eq!(got.reward.to_bits(), s.reward.to_bits());
        }
        // And stepping straight through from the first state.
        fresh.set_state(&ep.steps[0].state).unwrap();
        for s in &ep.steps {
            let got = fresh.step(&s.action).unwrap();
            assert_eq!(bits(got.obs), bits(&s.obs));
        }
    }
}

fn messages(path: &Path) -> Vec<(String, String, u64, serde_json::Value)> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            assert_eq!(m.channel.message_encoding, "json", "{}", m.channel.topic);
            let schema = m
                .channel
                .schema
                .as_ref()
                .expect("every channel has a schema");
            assert_eq!(schema.encoding, "jsonschema");
            let s: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
            assert!(s.is_object(), "schema of {}", m.channel.topic);
            let v: serde_json::Value = serde_json::from_slice(&m.data)
                .unwrap_or_else(|e| panic!("{}: {e}", m.channel.topic));
            (m.channel.topic.clone(), schema.name.clone(), m.log_time, v)
        })
        .collect()
}

#[test]
fn channels_decode_with_any_mcap_reader() {
    let path = common::scratch("decode.mcap");
    let mut env = env();
    let mut rec = Recorder::create(&path, &env).unwrap();
    let steps = 3;
    rec.reset(&mut env, Some(5)).unwrap();
    let dim = env.action_space().shape[0];
    for t in 0..steps {
        rec.step(&mut env, &action(dim, 0, t)).unwrap();
    }
    rec.end_episode(false).unwrap();
    rec.reset(&mut env, None).unwrap();
    rec.step(&mut env, &action(dim, 1, 0)).unwrap();
    rec.end_episode(false).unwrap();
    // A rejected action writes nothing.
    assert!(matches!(
        rec.step(&mut env, &[0.0]),
        Err(RecordError::Env { .. }) | Err(RecordError::Usage { .. })
    ));
    rec.finish().unwrap();

    // Header profile and metadata through the plain mcap crate.
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("summary");
    // One file-level record and one per episode (two episodes).
    assert_eq!(summary.metadata_indexes.len(), 3);
    let md = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).unwrap();
    assert_eq!(md.name, "mjskill");
    assert_eq!(md.metadata["env_id"], "PickCube-v1");
    for (k, index) in summary.metadata_indexes[1..].iter().enumerate() {
        let md = mcap::read::metadata(&bytes, index).unwrap();
        assert_eq!(md.name, format!("episode-{k}"));
        assert_eq!(md.metadata["episode"], k.to_string());
        assert_eq!(md.metadata["env_id"], "PickCube-v1");
        assert_eq!(md.metadata["control_mode"], "pd_joint_delta_pos");
        assert!(md.metadata["obs_layout"].contains("extra/tcp_pose"));
        assert_eq!(md.metadata["timestep"], "0.01");
    }
    let raw = record::read_raw(&path).unwrap();
    assert_eq!(raw.profile, "mjskill");
    assert_eq!(raw.episode_metadata.len(), 2);
    assert_eq!(raw.episode_metadata[0]["seed"], "5");
    assert_eq!(raw.episode_metadata[1]["seed"], "null", "unseeded reset");

    let msgs = messages(&path);
    let count = |t: &str| msgs.iter().filter(|m| m.0 == t).count();
    assert_eq!(count("/episode"), 2);
    assert_eq!(count("/episode_end"), 2);
    assert_eq!(count("/step"), steps + 1);
    assert_eq!(count("/scene"), 2);
    assert_eq!(count("/tf"), steps + 1 + 2);
    // Times never go backwards.
    for w in msgs.windows(2) {
        assert!(
            w[1].2 >= w[0].2,
            "{} at {} after {} at {}",
            w[1].0,
            w[1].2,
            w[0].0,
            w[0].2
        );
    }
    let nbody = env.model().nbody();
    for (topic, schema, time, v) in &msgs {
        match topic.as_str() {
            "/tf" => {
                assert_eq!(schema, "foxglove.FrameTransforms");
                let tr = v["transforms"].as_array().expect("transforms array");
                assert_eq!(tr.len(), nbody - 1);
                for t in tr {
                    assert_eq!(t["parent_frame_id"], "world");
                    assert!(t["child_frame_id"].as_str().is_some_and(|s| !s.is_empty()));
                    for k in ["x", "y", "z"] {
                        assert!(t["translation"][k].is_number(), "{t}");
                    }
                    for k in ["x", "y", "z", "w"] {
                        assert!(t["rotation"][k].is_number(), "{t}");
                    }
                    let ns = t["timestamp"]["sec"].as_u64().unwrap() * 1_000_000_000
                        + t["timestamp"]["nsec"].as_u64().unwrap();
                    assert_eq!(ns, *time);
                }
            }
            "/scene" => {
                assert_eq!(schema, "foxglove.SceneUpdate");
                let ents = v["entities"].as_array().expect("entities array");
                assert!(!ents.is_empty());
                let prims: usize = ents
                    .iter()
                    .map(|e| {
                        assert!(e["frame_id"].is_string());
                        ["cubes", "spheres", "cylinders"]
                            .iter()
                            .map(|k| e[k].as_array().unwrap().len())
                            .sum::<usize>()
                    })
                    .sum();
                assert!(prims > 0);
                let cube = ents
                    .iter()
                    .flat_map(|e| e["cubes"].as_array().unwrap())
                    .next()
                    .expect("a cube");
                for k in ["x", "y", "z"] {
                    assert!(cube["size"][k].as_f64().unwrap() > 0.0);
                }
                assert!(cube["color"]["a"].as_f64().unwrap() > 0.0);
            }
            "/step" => {
                assert_eq!(schema, "mjskill.Step");
                for k in ["action", "obs", "reward", "info", "state_before"] {
                    assert!(!v[k].is_null(), "{k}");
                }
                assert!(v["info"]["elapsed_steps"].is_number());
            }
            "/episode" => assert_eq!(schema, "mjskill.Episode"),
            "/episode_end" => {
                assert_eq!(schema, "mjskill.EpisodeEnd");
                assert!(v["return"].is_number());
            }
            other => panic!("unexpected topic {other}"),
        }
    }
}

#[test]
fn finished_episodes_survive_a_kill() {
    let path = common::scratch("killed.mcap");
    let mut env = env();
    let mut rec = Recorder::create(&path, &env).unwrap();
    let seen = record_episodes(&mut rec, &mut env, 0, 2, 4, true);
    record_episodes(&mut rec, &mut env, 2, 1, 3, false);
    // The moment of the kill: what is on disk now.
    let at_kill = std::fs::read(&path).unwrap();
    // A killed process runs no destructor (which would write the footer).
    std::mem::forget(rec);
    let copy = common::scratch("killed-copy.mcap");
    std::fs::write(&copy, &at_kill).unwrap();
    for p in [&path, &copy] {
        let r = record::read(p).unwrap();
        assert!(!r.complete, "{}", p.display());
        assert_eq!(r.finished().count(), 2);
        assert!(r.episodes.len() <= 3);
        for (ep, (_, _, steps)) in r.finished().zip(&seen) {
            assert_eq!(ep.steps.len(), steps.len());
            assert_eq!(bits(&ep.steps[3].obs), bits(&steps[3].obs));
        }
    }
}

#[test]
fn a_recorder_dropped_by_a_panic_never_claims_completeness() {
    let path = common::scratch("panicked.mcap");
    let r = std::panic::catch_unwind(|| {
        let mut env = env();
        let mut rec = Recorder::create(&path, &env).unwrap();
        record_episodes(&mut rec, &mut env, 0, 2, 4, true);
        record_episodes(&mut rec, &mut env, 2, 1, 3, false);
        panic!("a bug in the middle of episode 3");
    });
    assert!(r.is_err());
    let r = record::read(&path).unwrap();
    assert!(!r.complete);
    assert_eq!(r.finished().count(), 2);
}

#[test]
fn truncated_files_never_panic() {
    let path = common::scratch("full.mcap");
    let mut env = env();
    let mut rec = Recorder::create(&path, &env).unwrap();
    record_episodes(&mut rec, &mut env, 0, 2, 3, true);
    rec.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let full = record::read(&path).unwrap();
    assert_eq!(full.episodes.len(), 2);
    let cut = common::scratch("cut.mcap");
    let n = bytes.len();
    let mut sizes: Vec<usize> = (0..40).map(|k| k * n / 40).collect();
    sizes.extend([1, 7, 8, 9, 20, n - 1, n - 8, n - 9]);
    let mut ok = 0;
    for size in sizes {
        std::fs::write(&cut, &bytes[..size]).unwrap();
        match record::read(&cut) {
            Ok(r) => {
                ok += 1;
                assert!(!r.complete, "cut at {size} of {n}");
                assert!(r.episodes.len() <= 2);
                assert!(r.finished().count() <= 2);
                for (a, b) in r.finished().zip(&full.episodes) {
                    assert_eq!(a, b, "cut at {size}");
                }
            }
            Err(e) => {
                let msg = e.to_string();
                assert!(msg.contains(&cut.display().to_string()), "{msg}");
            }
        }
    }
    assert!(ok > 0);
    // Cut just before the footer: every episode is still there.
    std::fs::write(&cut, &bytes[..n - 9]).unwrap();
    assert_eq!(record::read(&cut).unwrap().finished().count(), 2);
}

#[test]
fn garbage_empty_and_foreign_files_are_errors_naming_the_file() {
    let garbage = common::scratch("garbage.mcap");
    std::fs::write(
        &garbage,
        b"this is not an mcap file at all, just some text\n",
    )
    .unwrap();
    let empty = common::scratch("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    let missing = common::scratch("does-not-exist.mcap");
    // A valid MCAP that is not an mjskill recording.
    let foreign = common::scratch("foreign.mcap");
    {
        let f = std::io::BufWriter::new(std::fs::File::create(&foreign).unwrap());
        let mut w = mcap::WriteOptions::new().profile("ros2").create(f).unwrap();
        w.finish().unwrap();
    }
    // Magic followed by garbage.
    let damaged = common::scratch("damaged.mcap");
    let mut d = mcap::MAGIC.to_vec();
    d.extend((0..500u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8));
    std::fs::write(&damaged, &d).unwrap();
    for p in [&garbage, &empty, &missing, &foreign, &damaged] {
        let e = record::read(p).expect_err(&p.display().to_string());
        assert!(
            e.to_string().contains(&p.display().to_string()),
            "error does not name the file: {e}"
        );
    }
}

#[test]
fn unwritable_path_fails_at_create() {
    let env = env();
    let p = common::scratch("no-such-dir").join("sub").join("x.mcap");
    let e = Recorder::create(&p, &env).expect_err("unwritable");
    assert!(e.to_string().contains(&p.display().to_string()), "{e}");
}
