//! Damaged and cut recordings: a damaged chunk is an error naming its offset, a cut file reads
//! up to the cut, no length in a file can make a reader abort, `--salvage` keeps what precedes
//! damage, and the recorder never writes a file it cannot read back. The last test is a fuzz
//! run (fixed seed, bounded count) of truncations and single-bit flips through `read`, `info`
//! and `replay`.
#![cfg(feature = "cli")]

mod common;
use std::path::Path;
use std::process::Command;

use mjskill::record::{self, RecordError, Recorder};
use mjskill::{make, Env, EnvConfig};
use rand::{Rng, SeedableRng};

fn mjskill() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mjskill"))
}

fn env() -> Env {
    make("PickCube-v1", EnvConfig::default()).unwrap()
}

/// Records `episodes` finished episodes of `steps` steps (seeds 3, 4, ...); `killed` adds an
/// unfinished episode and abandons the recorder as a kill would leave the file.
fn record_file(path: &Path, episodes: usize, steps: usize, killed: bool) {
    let mut env = env();
    let mut rec = Recorder::create(path, &env).unwrap();
    let dim = env.action_space().shape[0];
    for ep in 0..episodes + usize::from(killed) {
        rec.reset(&mut env, Some(3 + ep as u64)).unwrap();
        let n = if ep < episodes { steps } else { 2 };
        for t in 0..n {
            let a: Vec<f32> = (0..dim)
                .map(|i| ((i * 3 + t + ep) as f32 * 0.7).sin())
                .collect();
            rec.step(&mut env, &a).unwrap();
        }
        if ep < episodes {
            rec.end_episode(false).unwrap();
        }
    }
    if killed {
        rec.abandon().unwrap();
    } else {
        rec.finish().unwrap();
    }
}

/// Top-level records of an MCAP file: (opcode, offset, total length).
fn records(b: &[u8]) -> Vec<(u8, usize, usize)> {
    let mut out = Vec::new();
    let mut off = 8;
    while off + 9 <= b.len() {
        let op = b[off];
        let len = u64::from_le_bytes(b[off + 1..off + 9].try_into().unwrap()) as usize;
        if off + 9 + len > b.len() {
            break;
        }
        out.push((op, off, 9 + len));
        off += 9 + len;
        if op == 0x02 {
            break;
        }
    }
    out
}

const CHUNK: u8 = 0x06;

fn chunks(b: &[u8]) -> Vec<(usize, usize)> {
    records(b)
        .into_iter()
        .filter(|r| r.0 == CHUNK)
        .map(|r| (r.1, r.2))
        .collect()
}

fn flipped(b: &[u8], at: usize, bit: u8) -> Vec<u8> {
    let mut v = b.to_vec();
    v[at] ^= 1 << bit;
    v
}

fn is_corrupt(e: &RecordError) -> bool {
    matches!(e, RecordError::Corrupt { .. })
}

#[test]
fn a_damaged_chunk_is_an_error_naming_its_offset_never_a_cut() {
    for killed in [false, true] {
        let path = common::scratch(&format!("chunks-{killed}.mcap"));
        record_file(&path, 2, 6, killed);
        let bytes = std::fs::read(&path).unwrap();
        let cs = chunks(&bytes);
        assert!(cs.len() >= 3, "{cs:?}");
        let bad = common::scratch(&format!("chunks-{killed}-bad.mcap"));
        for (k, &(off, len)) in cs.iter().enumerate() {
            // The compressed data, and every field of the chunk header (times, sizes, CRC).
            let clen = u32::from_le_bytes(bytes[off + 37..off + 41].try_into().unwrap()) as usize;
            let data = off + 9 + 40 + clen;
            let mut spots = vec![
                off + 1,
                off + 9,
                off + 17,
                off + 25,
                off + 33,
                off + 41 + clen,
            ];
            spots.extend([data, data + (off + len - data) / 2, off + len - 1]);
            for at in spots {
                std::fs::write(&bad, flipped(&bytes, at, 3)).unwrap();
                let e = record::read(&bad).expect_err(&format!("flip at {at} in chunk {k}"));
                let msg = e.to_string();
                assert!(
                    is_corrupt(&e),
                    "flip at {at} (chunk {k}, killed {killed}): {msg}"
                );
                assert!(
                    msg.contains(&format!("byte offset {off}")) && msg.contains("chunk"),
                    "{msg}"
                );
                // Through the command line: exit 2 naming the chunk, not "complete": false.
                if at == data {
                    let o = mjskill().arg("info").arg(&bad).output().unwrap();
                    assert_eq!(o.status.code(), Some(2));
                    assert!(String::from_utf8_lossy(&o.stderr).contains(&format!("chunk {k}")));
                }
            }
        }
    }
}

/// Patches an uncompressed copy of a recording: the length field of the first message
/// inside the first chunk with messages becomes `len`, and the chunk CRC is recomputed, so the
/// only thing wrong is the length.
fn with_record_length(len: u64) -> Vec<u8> {
    let path = common::scratch("plain.mcap");
    {
        let f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = mcap::WriteOptions::new()
            .profile("mjskill")
            .compression(None)
            .create(f)
            .unwrap();
        let s = w.add_schema("s", "jsonschema", b"{}").unwrap();
        let c = w
            .add_channel(s, "/episode", "json", &Default::default())
            .unwrap();
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: c,
                sequence: 0,
                log_time: 0,
                publish_time: 0,
            },
            b"{\"episode\": 0}",
        )
        .unwrap();
        w.finish().unwrap();
    }
    let mut b = std::fs::read(&path).unwrap();
    let (off, _) = chunks(&b)[0];
    let data = off + 9 + 40; // no compression name
    let size = u64::from_le_bytes(b[off + 25..off + 33].try_into().unwrap()) as usize;
    // Walk the chunk's records to the message (opcode 5).
    let mut r = data;
    while b[r] != 0x05 {
        r += 9 + u64::from_le_bytes(b[r + 1..r + 9].try_into().unwrap()) as usize;
    }
    b[r + 1..r + 9].copy_from_slice(&len.to_le_bytes());
    let crc = crc32fast::hash(&b[data..data + size]);
    b[off + 33..off + 37].copy_from_slice(&crc.to_le_bytes());
    b
}

#[test]
fn a_huge_record_length_is_an_error_not_an_abort() {
    // 4e18 bytes: the length that made `mjskill info` abort with a failed allocation.
    for len in [4_000_000_000_000_000_000u64, 1 << 40, u64::MAX] {
        let path = common::scratch("huge.mcap");
        std::fs::write(&path, with_record_length(len)).unwrap();
        let e = record::read_raw(&path).unwrap_err();
        assert!(is_corrupt(&e), "{e}");
        assert!(e.to_string().contains("limit"), "{e}");
        let o = mjskill().arg("info").arg(&path).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "an error exit, not SIGABRT");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("damaged at byte offset"), "{err}");
    }
}

#[test]
fn cut_files_read_up_to_the_cut_and_say_truncated_before_the_metadata() {
    let path = common::scratch("cut-source.mcap");
    record_file(&path, 2, 5, false);
    let bytes = std::fs::read(&path).unwrap();
    let full = record::read(&path).unwrap();
    let first_chunk = chunks(&bytes)[0].0;
    let cut = common::scratch("cut.mcap");
    // Every cut before the first chunk: the metadata (bytes ~45..~1400) is incomplete or the
    // file ends right after it.
    for n in 1..first_chunk {
        std::fs::write(&cut, &bytes[..n]).unwrap();
        match record::read(&cut) {
            Err(e @ RecordError::Truncated { .. }) => {
                let m = e.to_string();
                assert!(
                    m.contains("truncated") && m.contains(&format!("at byte {n}")),
                    "{m}"
                );
            }
            Ok(r) => {
                assert!(!r.complete && r.episodes.is_empty(), "cut at {n}");
            }
            Err(e) => panic!("cut at {n}: {e}"),
        }
    }
    // Through the command line (the report of the issue: bytes 45..837).
    for n in [45, 100, 500, 837] {
        std::fs::write(&cut, &bytes[..n]).unwrap();
        let o = mjskill().arg("info").arg(&cut).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2));
        assert!(
            err.contains("truncated") && !err.contains("no \"mjskill\" metadata record"),
            "{err}"
        );
    }
    // Every cut after it: a readable prefix, never "damaged".
    for n in (first_chunk..bytes.len())
        .step_by(97)
        .chain([bytes.len() - 1])
    {
        std::fs::write(&cut, &bytes[..n]).unwrap();
        let r = record::read(&cut).unwrap_or_else(|e| panic!("cut at {n}: {e}"));
        assert!(!r.complete);
        for (a, b) in r.finished().zip(full.finished()) {
            assert_eq!(a, b, "cut at {n}");
        }
    }
}

#[test]
fn a_closed_file_with_a_flipped_bit_anywhere_is_damaged() {
    // Every byte of a closed file is covered by a chunk CRC, the data-section CRC, the summary
    // CRC or a structure check: flips in the header, metadata, message indexes, summary and
    // footer are errors too (spot checks over each record kind).
    let path = common::scratch("closed.mcap");
    record_file(&path, 1, 3, false);
    let bytes = std::fs::read(&path).unwrap();
    let bad = common::scratch("closed-bad.mcap");
    let mut kinds = std::collections::BTreeSet::new();
    for (op, off, len) in records(&bytes) {
        kinds.insert(op);
        for at in [off, off + 1, off + 9, off + len / 2, off + len - 1] {
            std::fs::write(&bad, flipped(&bytes, at, 0)).unwrap();
            let r = record::read(&bad);
            assert!(
                r.is_err(),
                "flip at {at} in the record {op:#04x} at {off} went unseen"
            );
        }
    }
    // Header, metadata, chunk, message index, data end, summary records, footer.
    assert!(kinds.len() >= 8, "{kinds:?}");
    for at in [0, 7, bytes.len() - 1] {
        std::fs::write(&bad, flipped(&bytes, at, 5)).unwrap();
        assert!(record::read(&bad).is_err(), "magic flip at {at}");
    }
}

#[test]
fn salvage_reads_what_precedes_the_damage() {
    let path = common::scratch("salvage.mcap");
    record_file(&path, 3, 4, false);
    let bytes = std::fs::read(&path).unwrap();
    // Damage the last chunk that holds messages: the episodes before it stay readable.
    let (off, len) = *chunks(&bytes).last().unwrap();
    let bad = common::scratch("salvage-bad.mcap");
    std::fs::write(&bad, flipped(&bytes, off + len - 2, 1)).unwrap();
    let o = mjskill().arg("info").arg(&bad).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let o = mjskill()
        .args(["info", "--salvage"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let i: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(i["complete"], false);
    assert!(i["episodes"].as_u64().unwrap() >= 2, "{i}");
    assert!(
        i["damage"]
            .as_str()
            .unwrap()
            .contains(&format!("byte offset {off}")),
        "{i}"
    );
    let o = mjskill()
        .args(["replay", "--salvage", "--tolerance", "0"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["episodes"], i["episodes"]);
    assert_eq!(r["ok"], true);
    assert!(r["damage"].is_string());
}

#[test]
fn the_recorder_refuses_what_it_could_not_read_back() {
    let path = common::scratch("refused.mcap");
    let mut env = env();
    let mut rec = Recorder::create(&path, &env).unwrap();
    rec.reset(&mut env, Some(1)).unwrap();
    let dim = env.action_space().shape[0];
    rec.step(&mut env, &vec![0.1; dim]).unwrap();
    // A state holding NaN (a diverged env): refused before anything is written.
    let mut state = env.get_state();
    state.physics[3] = f64::NAN;
    let s = env.step(&vec![0.0; dim]).unwrap();
    let (reward, term, trunc) = (s.reward, s.terminated, s.truncated);
    let e = rec
        .record_step(&env, &vec![0.0; dim], reward, term, trunc, &state)
        .unwrap_err();
    assert!(matches!(e, RecordError::Refused { .. }), "{e}");
    assert!(
        e.to_string().contains("state_before.physics[3] = NaN"),
        "{e}"
    );
    state.physics[3] = 0.0;
    state.controller[0] = f64::INFINITY;
    let e = rec
        .record_step(&env, &vec![0.0; dim], reward, term, trunc, &state)
        .unwrap_err();
    assert!(e.to_string().contains("controller[0] = inf"), "{e}");
    // A message larger than the readers accept (~36 MB of JSON on a channel of the caller's).
    let ch = rec
        .add_json_channel("test.Big", &serde_json::json!({"type": "object"}), "/big")
        .unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let noise: String = (0..36_000_000)
        .map(|_| (b'a' + rng.random_range(0..26u8)) as char)
        .collect();
    let e = rec
        .write_message(ch, &serde_json::json!({ "noise": noise }))
        .unwrap_err();
    assert!(e.to_string().contains("MiB"), "{e}");
    if cfg!(feature = "video") {
        // A frame of an odd size cannot be H.264: refused, nothing written.
        rec.enable_video("render_camera").unwrap();
        let e = rec.record_frame(&[0; 3 * 3 * 3], 3, 3).unwrap_err();
        assert!(e.to_string().contains("even"), "{e}");
    } else {
        // Without the `video` feature, video is refused naming the feature; nothing written.
        let e = rec.enable_video("render_camera").unwrap_err();
        assert!(e.to_string().contains("`video` feature"), "{e}");
    }
    rec.end_episode(false).unwrap();
    rec.finish().unwrap();
    // The file is complete and reads back with the one good step.
    let r = record::read(&path).unwrap();
    assert!(r.complete);
    assert_eq!(r.episodes[0].steps.len(), 1);
    let info = mjskill().arg("info").arg(&path).output().unwrap();
    assert!(String::from_utf8_lossy(&info.stdout).contains("\"complete\":true"));
}

/// The fuzz run: a fixed seed, a bounded count. Truncations and single-bit flips of a closed
/// and a killed recording through `read` (no panic; a flip inside a chunk, or anywhere in a
/// closed file, is an error; anything read equals the original; a cut is never "damaged"),
/// and a subset through `mjskill info` and `mjskill replay` (exit 0 or 2, never a signal or a
/// panic).
#[test]
fn fuzz_truncations_and_bit_flips() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(18);
    let (mut flips, mut cuts, mut cli, mut unused_bits) = (0, 0, 0, 0);
    for killed in [false, true] {
        let path = common::scratch(&format!("fuzz-{killed}.mcap"));
        record_file(&path, 2, 5, killed);
        let bytes = std::fs::read(&path).unwrap();
        let orig = record::read(&path).unwrap();
        let in_chunk = |at: usize| {
            chunks(&bytes)
                .iter()
                .any(|&(o, l)| (o..o + l).contains(&at))
        };
        // Not covered without a summary: the header's library name, and the seed in the
        // metadata of an episode none of whose messages reached the file.
        let recs = records(&bytes);
        let unchecked: Vec<(usize, usize)> = std::iter::once(recs[0])
            .chain(recs.last().copied().filter(|r| killed && r.0 == 0x0C))
            .map(|(_, o, l)| (o, o + l))
            .collect();
        let bad = common::scratch(&format!("fuzz-{killed}-bad.mcap"));
        for k in 0..500 {
            let cut = k % 3 == 0;
            let (data, at) = if cut {
                let n = rng.random_range(1..bytes.len());
                (bytes[..n].to_vec(), n)
            } else {
                let at = rng.random_range(0..bytes.len());
                (flipped(&bytes, at, rng.random_range(0..8)), at)
            };
            std::fs::write(&bad, &data).unwrap();
            let r = std::panic::catch_unwind(|| record::read(&bad))
                .unwrap_or_else(|_| panic!("read panicked (cut {cut}, at {at})"));
            match (&r, cut) {
                (Ok(rec), true) => {
                    cuts += 1;
                    assert!(!rec.complete, "cut at {at}");
                    for (a, b) in rec.finished().zip(orig.finished()) {
                        assert_eq!(a, b, "cut at {at}");
                    }
                }
                (Err(e), true) => {
                    cuts += 1;
                    assert!(!is_corrupt(e), "a cut at {at} read as damage: {e}");
                }
                (Ok(rec), false) if in_chunk(at) => {
                    // A bit the compressed stream does not use (zstd's bitstream padding)
                    // decodes to the same records, which the CRC of the uncompressed data
                    // then vouches for: nothing read may differ, and such bits are rare.
                    flips += 1;
                    unused_bits += 1;
                    assert_eq!(rec.meta, orig.meta, "flip at {at}");
                    assert_eq!(rec.episodes, orig.episodes, "flip at {at}");
                }
                (Ok(rec), false) => {
                    flips += 1;
                    assert!(killed, "flip at {at} of a closed file went unseen");
                    assert!(
                        unchecked.iter().any(|&(a, b)| (a..b).contains(&at)),
                        "flip at {at} went unseen"
                    );
                    // Whatever was read is unchanged.
                    assert_eq!(rec.meta, orig.meta);
                    assert_eq!(rec.episodes, orig.episodes, "flip at {at}");
                }
                (Err(e), false) => {
                    flips += 1;
                    if in_chunk(at) {
                        assert!(is_corrupt(e), "flip at {at}: {e}");
                    }
                }
            }
            if k % 20 == 0 {
                cli += 1;
                let cmd = if k % 60 == 0 { "replay" } else { "info" };
                let o = mjskill().arg(cmd).arg(&bad).output().unwrap();
                let err = String::from_utf8_lossy(&o.stderr);
                assert!(
                    matches!(o.status.code(), Some(0) | Some(2)),
                    "{cmd} at {at}: {:?} {err}",
                    o.status
                );
                assert!(!err.contains("panicked"), "{err}");
            }
        }
    }
    assert_eq!(flips + cuts, 1000);
    assert!(
        unused_bits <= 3,
        "{unused_bits} flips inside chunks changed nothing read"
    );
    assert_eq!(cli, 50);
}

/// Writes `raw` (read by `record::read_raw`) again as an MCAP file at `path`, every CRC
/// written, each message's JSON passed through `edit(topic, message)`: the episode metadata
/// records before their `/episode` messages, as the recorder writes them.
fn rewrite(raw: &record::RawRecording, path: &Path, edit: impl Fn(&str, &mut serde_json::Value)) {
    use mcap::records::{MessageHeader, Metadata};
    use std::collections::BTreeMap;
    let f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut w = mcap::WriteOptions::new()
        .profile(&raw.profile)
        .library(&raw.library)
        .create(f)
        .unwrap();
    w.write_metadata(&Metadata {
        name: "mjskill".into(),
        metadata: raw.metadata.clone(),
    })
    .unwrap();
    let mut channels = BTreeMap::new();
    let mut episode = 0;
    for (seq, m) in raw.messages.iter().enumerate() {
        if m.topic == "/episode" {
            w.write_metadata(&Metadata {
                name: format!("episode-{episode}"),
                metadata: raw.episode_metadata[episode].clone(),
            })
            .unwrap();
            episode += 1;
        }
        if !channels.contains_key(&m.topic) {
            let sid = w.add_schema(&m.schema, "jsonschema", b"{}").unwrap();
            let ch = w
                .add_channel(sid, &m.topic, &m.encoding, &BTreeMap::new())
                .unwrap();
            channels.insert(m.topic.clone(), ch);
        }
        let mut v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        edit(&m.topic, &mut v);
        let header = MessageHeader {
            channel_id: channels[&m.topic],
            sequence: seq as u32,
            log_time: m.log_time,
            publish_time: m.log_time,
        };
        w.write_to_known_channel(&header, &serde_json::to_vec(&v).unwrap())
            .unwrap();
    }
    w.finish().unwrap();
}

/// The SO100's jaw release counters in a recorded state (issue 57): `mjskill info` and
/// `mjskill replay` refuse a recording whose counters `set_state` refuses (−3, 2^40), naming
/// the episode, the step and the value, as they read the recording it was made from; the
/// recorder never writes such a state.
#[test]
fn recorded_jaw_release_counters_are_checked_as_set_state_checks_them() {
    let path = common::scratch("so100_counters.mcap");
    let mut env = make("PickCubeSO100-v1", EnvConfig::default()).unwrap();
    let mut rec = Recorder::create(&path, &env).unwrap();
    rec.reset(&mut env, Some(3)).unwrap();
    let dim = env.action_space().shape[0];
    for t in 0..4 {
        rec.step(&mut env, &vec![0.1 * t as f32; dim]).unwrap();
    }
    rec.end_episode(false).unwrap();
    let n_ctl = env.get_state().controller.len();
    let counter = n_ctl - env.drives().len();
    // The recorder refuses a state whose counter set_state refuses; nothing is written.
    let mut state = env.get_state();
    state.controller[counter] = -3.0;
    rec.reset(&mut env, Some(4)).unwrap();
    let s = env.step(&vec![0.0; dim]).unwrap();
    let (reward, term, trunc) = (s.reward, s.terminated, s.truncated);
    let e = rec
        .record_step(&env, &vec![0.0; dim], reward, term, trunc, &state)
        .unwrap_err();
    assert!(
        e.to_string().contains("jaw release count") && e.to_string().contains("= -3"),
        "{e}"
    );
    rec.end_episode(false).unwrap();
    rec.finish().unwrap();
    let raw = record::read_raw(&path).unwrap();
    let run = |cmd: &str, p: &Path| mjskill().arg(cmd).arg(p).output().unwrap();
    // The file as recorded, and written again unchanged: both read and replay.
    let same = common::scratch("so100_counters_same.mcap");
    rewrite(&raw, &same, |_, _| {});
    for p in [&path, &same] {
        for cmd in ["info", "replay"] {
            let o = run(cmd, p);
            assert!(
                o.status.success(),
                "{cmd}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
        }
    }
    for bad in [-3.0, 2f64.powi(40), 0.5] {
        let cases = [
            (
                "/step",
                "episode 0, the state before step 2",
                "recorded state before step 2",
            ),
            (
                "/episode",
                "episode 0, its initial state",
                "recorded initial state",
            ),
        ];
        for (topic, info_at, replay_at) in cases {
            let out = common::scratch(&format!("so100_counter_{bad}_{}.mcap", &topic[1..]));
            rewrite(&raw, &out, |t, v| {
                if t == topic && v["episode"] == 0 && (t == "/episode" || v["step"] == 2) {
                    let key = if t == "/step" {
                        "state_before"
                    } else {
                        "state"
                    };
                    v[key]["controller"][counter] = serde_json::json!(bad);
                }
            });
            for cmd in ["info", "replay"] {
                let e = common::fails(&run(cmd, &out));
                let want = format!("controller[{counter}] = {bad} is not a jaw release count");
                assert!(e.contains(&want), "{cmd} {topic} {bad}: {e}");
                let at = if cmd == "info" { info_at } else { replay_at };
                assert!(
                    e.contains("episode 0") && e.contains(at),
                    "{cmd} {topic}: {e}"
                );
            }
        }
    }
}
