//! JSON Schemas of the recording's channels and the Foxglove message builders.
//!
//! The Foxglove schemas are the published JSON schemas of `@foxglove/schemas` 2.1.0 (MIT
//! licence), embedded verbatim from `foxglove/*.json`; the messages written fill every field
//! they require. The mjskill schemas list every field written (`additionalProperties: false`).

use serde_json::{json, Value};

use crate::mujoco::{BodyId, Data, GeomId, Model, ObjType, Pose};

fn num_or_null() -> Value {
    json!({ "type": ["number", "null"] })
}

fn num_array() -> Value {
    json!({ "type": "array", "items": num_or_null() })
}

fn info_object() -> Value {
    json!({
        "type": "object",
        "description": "elapsed_steps followed by the task's evaluate() keys (bools as 0/1)",
        "additionalProperties": num_or_null()
    })
}

fn u32_array(len: usize) -> Value {
    json!({
        "type": "array",
        "items": { "type": "integer", "minimum": 0, "maximum": 4294967295u64 },
        "minItems": len,
        "maxItems": len
    })
}

fn mt19937() -> Value {
    json!({
        "type": "object",
        "description": "MT19937 state: the 624 words and the index of the next word",
        "properties": {
            "state": u32_array(624),
            "index": { "type": "integer", "minimum": 0, "maximum": 624 }
        },
        "required": ["state", "index"],
        "additionalProperties": false
    })
}

fn env_state() -> Value {
    let seed = json!({ "type": ["integer", "null"], "minimum": 0 });
    json!({
        "type": "object",
        "description": "mjskill EnvState (Env::get_state / Env::set_state): every field written",
        "properties": {
            "env_id": { "type": "string" },
            "robot": { "type": "string" },
            "control_mode": { "type": "string" },
            "physics": {
                "type": "array",
                "description": "MuJoCo state: time, qpos, qvel, act, ctrl, qacc_warmstart, \
                                qfrc_applied, xfrc_applied, mocap_pos, mocap_quat",
                "items": { "type": "number" }
            },
            "controller": {
                "type": "array",
                "description": "controller targets, then the drive targets, (SO100) the jaw's release counters and (WidowX AI, xArm6) the pinch's kick flag",
                "items": { "type": "number" }
            },
            "elapsed_steps": { "type": "integer", "minimum": 0, "maximum": 4294967294u64 },
            "finger_forces": {
                "type": "array",
                "description": "contact forces on the two fingers in the last substep",
                "items": {
                    "type": "array",
                    "items": { "type": "number" },
                    "minItems": 3,
                    "maxItems": 3
                },
                "minItems": 2,
                "maxItems": 2
            },
            "numpy": numpy("numpy RandomState of the episode (joint noise)"),
            "main_numpy": {
                "anyOf": [
                    numpy("numpy RandomState of the main RNG (draws the episode seed of an \
                           unseeded reset of a task whose shapes change every episode)"),
                    { "type": "null" }
                ]
            },
            "geometry": {
                "type": "array",
                "description": "the episode's shapes of a task that draws them every episode \
                                (PegInsertionSide-v1: peg half length, radius, hole y, hole z); \
                                empty for the others",
                "items": { "type": "number" }
            },
            "torch_global": {
                "type": "object",
                "description": "the global torch generator (unseeded resets)",
                "properties": {
                    "seed": { "type": "integer", "minimum": 0 },
                    "mt": mt19937()
                },
                "required": ["seed", "mt"],
                "additionalProperties": false
            },
            "seeds": {
                "type": "array",
                "description": "main and episode seeds",
                "items": seed,
                "minItems": 2,
                "maxItems": 2
            }
        },
        "required": ["env_id", "robot", "control_mode", "physics", "controller", "elapsed_steps",
                     "finger_forces", "numpy", "torch_global", "seeds"],
        "additionalProperties": false
    })
}

/// Schema of a numpy `RandomState` (an MT19937 and the cached Gaussian), described as `what`.
fn numpy(what: &str) -> Value {
    json!({
        "type": "object",
        "description": what,
        "properties": {
            "mt": mt19937(),
            "gauss_bits": {
                "type": ["integer", "null"],
                "minimum": 0,
                "description": "IEEE-754 bits of the cached Gaussian"
            }
        },
        "required": ["mt", "gauss_bits"],
        "additionalProperties": false
    })
}

/// Schema of `/episode`.
pub(crate) fn episode() -> Value {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "mjskill.Episode",
        "description": "Start of an episode, written right after reset",
        "type": "object",
        "properties": {
            "episode": { "type": "integer", "minimum": 0 },
            "seed": { "type": ["integer", "null"] },
            "state": env_state(),
            "obs": num_array(),
            "info": info_object()
        },
        "required": ["episode", "seed", "state", "obs", "info"],
        "additionalProperties": false
    })
}

/// Schema of `/step`.
pub(crate) fn step() -> Value {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "mjskill.Step",
        "description": "One env step; state_before restarts the step exactly",
        "type": "object",
        "properties": {
            "episode": { "type": "integer", "minimum": 0 },
            "step": { "type": "integer", "minimum": 0 },
            "action": num_array(),
            "expert_action": {
                "type": "array",
                "items": num_or_null(),
                "description": "the expert's own action for the state before the step, where \
                                action is the one executed (rollout --action-noise: the \
                                policy's action plus noise); only in labelled recordings"
            },
            "obs": num_array(),
            "reward": num_or_null(),
            "terminated": { "type": "boolean" },
            "truncated": { "type": "boolean" },
            "info": info_object(),
            "state_before": env_state()
        },
        "required": ["episode", "step", "action", "obs", "reward", "terminated", "truncated",
                     "info", "state_before"],
        "additionalProperties": false
    })
}

/// Schema of `/episode_end`.
pub(crate) fn episode_end() -> Value {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "mjskill.EpisodeEnd",
        "type": "object",
        "properties": {
            "episode": { "type": "integer", "minimum": 0 },
            "steps": { "type": "integer", "minimum": 0 },
            "return": num_or_null(),
            "success": { "type": "boolean" }
        },
        "required": ["episode", "steps", "return", "success"],
        "additionalProperties": false
    })
}

/// A published Foxglove schema, embedded verbatim (`foxglove/*.json`).
fn published(text: &str) -> Value {
    // The files are part of the source and checked by the unit test below.
    serde_json::from_str(text).unwrap_or(Value::Null)
}

/// Schema `foxglove.FrameTransforms`: `@foxglove/schemas` 2.1.0, verbatim.
pub(crate) fn frame_transforms() -> Value {
    published(include_str!("foxglove/FrameTransforms.json"))
}

/// Schema `foxglove.SceneUpdate`: `@foxglove/schemas` 2.1.0, verbatim.
pub(crate) fn scene_update() -> Value {
    published(include_str!("foxglove/SceneUpdate.json"))
}

/// `{sec, nsec}` of a time in nanoseconds.
pub(crate) fn time(ns: u64) -> Value {
    json!({ "sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000 })
}

/// Frame name of body `b` (`"world"` for body 0, `body<b>` for unnamed bodies).
pub(crate) fn body_frames(model: &Model) -> Vec<String> {
    (0..model.nbody())
        .map(|b| {
            let n = model.name(ObjType::Body, b);
            if b == 0 {
                "world".to_string()
            } else if n.is_empty() {
                format!("body{b}")
            } else {
                n
            }
        })
        .collect()
}

/// `foxglove.FrameTransforms` with one transform per body (but the world body).
pub(crate) fn frame_transforms_msg(data: &Data, frames: &[String], ns: u64) -> Value {
    let t = time(ns);
    let transforms: Vec<Value> = (1..frames.len())
        .map(|b| {
            let Pose { pos: p, quat: q } = data.body_pose(BodyId::from_index(b));
            json!({
                "timestamp": t,
                "parent_frame_id": "world",
                "child_frame_id": frames[b],
                "translation": { "x": p[0], "y": p[1], "z": p[2] },
                "rotation": { "x": q[1], "y": q[2], "z": q[3], "w": q[0] }
            })
        })
        .collect();
    json!({ "transforms": transforms })
}

// mjtGeom
const GEOM_PLANE: i32 = 0;
const GEOM_SPHERE: i32 = 2;
const GEOM_CAPSULE: i32 = 3;
const GEOM_ELLIPSOID: i32 = 4;
const GEOM_CYLINDER: i32 = 5;
const GEOM_BOX: i32 = 6;
const GEOM_MESH: i32 = 7;

/// `foxglove.SceneUpdate` with one entity per body holding its drawn geoms in the body frame:
/// boxes and planes (1 mm thick, 4 m for infinite planes) as cubes, spheres and ellipsoids as
/// spheres, cylinders and capsules as cylinders, meshes as the box of their `geom_size`.
/// Invisible geoms (alpha 0) and collision shapes (group
/// [`crate::mjcf::GROUP_COLLISION`]) are skipped.
pub(crate) fn scene_update_msg(model: &Model, frames: &[String], ns: u64) -> Value {
    let t = time(ns);
    let ty = model.geom_type();
    let (body, group) = (model.geom_bodyid(), model.geom_group());
    let mut per_body: Vec<[Vec<Value>; 3]> = vec![Default::default(); frames.len()];
    for g in 0..model.ngeom() {
        let id = GeomId::from_index(g);
        let c = model.geom_color(id);
        if c[3] <= 0.0 || group[g] == crate::mjcf::GROUP_COLLISION {
            continue;
        }
        let s = model.geom_dims(id);
        let Pose { pos: p, quat: q } = model.geom_local_pose(id);
        let (kind, dims, pz) = match ty[g] {
            GEOM_BOX => (0, [2.0 * s[0], 2.0 * s[1], 2.0 * s[2]], 0.0),
            GEOM_MESH if s.iter().all(|&x| x > 0.0) => {
                (0, [2.0 * s[0], 2.0 * s[1], 2.0 * s[2]], 0.0)
            }
            GEOM_PLANE => {
                let e = |h: f64| if h > 0.0 { 2.0 * h } else { 4.0 };
                (0, [e(s[0]), e(s[1]), 0.001], -0.0005)
            }
            GEOM_SPHERE => (1, [2.0 * s[0]; 3], 0.0),
            GEOM_ELLIPSOID => (1, [2.0 * s[0], 2.0 * s[1], 2.0 * s[2]], 0.0),
            GEOM_CYLINDER => (2, [2.0 * s[0], 2.0 * s[0], 2.0 * s[1]], 0.0),
            GEOM_CAPSULE => (2, [2.0 * s[0], 2.0 * s[0], 2.0 * (s[1] + s[0])], 0.0),
            _ => continue,
        };
        let b = usize::try_from(body[g]).unwrap_or(0).min(frames.len() - 1);
        let mut prim = json!({
            "pose": {
                "position": { "x": p[0], "y": p[1], "z": p[2] + pz },
                "orientation": { "x": q[1], "y": q[2], "z": q[3], "w": q[0] }
            },
            "size": { "x": dims[0], "y": dims[1], "z": dims[2] },
            "color": { "r": c[0], "g": c[1], "b": c[2], "a": c[3] }
        });
        if kind == 2 {
            prim["bottom_scale"] = json!(1.0);
            prim["top_scale"] = json!(1.0);
        }
        per_body[b][kind].push(prim);
    }
    let entities: Vec<Value> = per_body
        .into_iter()
        .enumerate()
        .filter(|(_, p)| p.iter().any(|v| !v.is_empty()))
        .map(|(b, [cubes, spheres, cylinders])| {
            json!({
                "timestamp": t,
                "frame_id": frames[b],
                "id": frames[b],
                "lifetime": { "sec": 0, "nsec": 0 },
                "frame_locked": true,
                "metadata": [],
                "arrows": [],
                "cubes": cubes,
                "spheres": spheres,
                "cylinders": cylinders,
                "lines": [],
                "triangles": [],
                "texts": [],
                "models": []
            })
        })
        .collect();
    json!({ "deletions": [], "entities": entities })
}

/// Schema `foxglove.CompressedImage` (JSON encoding: `data` is base64): `@foxglove/schemas`
/// 2.1.0, verbatim.
#[cfg(test)]
pub(crate) fn compressed_image() -> Value {
    published(include_str!("foxglove/CompressedImage.json"))
}

/// Schema `foxglove.CompressedVideo` (JSON encoding: `data` is base64): `@foxglove/schemas`
/// 2.1.0, verbatim.
pub(crate) fn compressed_video() -> Value {
    published(include_str!("foxglove/CompressedVideo.json"))
}

/// A `foxglove.CompressedImage` (or, with the same fields, `foxglove.CompressedVideo`)
/// message with base64 `data`.
#[derive(serde::Serialize, serde::Deserialize)]
#[cfg_attr(not(feature = "video"), allow(dead_code))]
pub(crate) struct CompressedImageMsg<'a> {
    pub(crate) timestamp: Value,
    pub(crate) frame_id: &'a str,
    pub(crate) data: &'a str,
    pub(crate) format: &'a str,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every `"type": "array"` in `v` has an item schema, every object with properties lists
    /// the required ones; returns the paths that break the rule.
    fn loose(v: &Value, path: &str, out: &mut Vec<String>) {
        if let Some(o) = v.as_object() {
            if o.get("type") == Some(&json!("array")) && !o.contains_key("items") {
                out.push(format!("{path}: array without items"));
            }
            for (k, c) in o {
                loose(c, &format!("{path}/{k}"), out);
            }
        } else if let Some(a) = v.as_array() {
            for (i, c) in a.iter().enumerate() {
                loose(c, &format!("{path}/{i}"), out);
            }
        }
    }

    #[test]
    fn schemas_are_complete() {
        for (name, s) in [
            ("foxglove.FrameTransforms", frame_transforms()),
            ("foxglove.SceneUpdate", scene_update()),
            ("foxglove.CompressedImage", compressed_image()),
            ("foxglove.CompressedVideo", compressed_video()),
            ("mjskill.Episode", episode()),
            ("mjskill.Step", step()),
            ("mjskill.EpisodeEnd", episode_end()),
        ] {
            assert_eq!(s["title"], json!(name));
            let mut bad = Vec::new();
            loose(&s, name, &mut bad);
            assert!(bad.is_empty(), "{bad:?}");
        }
        // The published SceneUpdate: required lists, the deletion type as a oneOf of consts.
        let su = scene_update();
        let del = &su["properties"]["deletions"]["items"];
        assert_eq!(del["required"], json!(["timestamp", "type", "id"]));
        assert_eq!(del["properties"]["type"]["oneOf"][1]["const"], json!(1));
        let ent = &su["properties"]["entities"]["items"];
        assert_eq!(ent["required"].as_array().map(Vec::len), Some(14));
        for k in ["arrows", "lines", "triangles", "texts", "models"] {
            assert!(ent["properties"][k]["items"]["required"].is_array(), "{k}");
        }
        // The state schema names every field of EnvState.
        let st = &episode()["properties"]["state"];
        let required: Vec<&str> = st["required"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(Value::as_str)
            .collect();
        for k in ["finger_forces", "numpy", "torch_global", "seeds"] {
            assert!(required.contains(&k), "{k}");
        }
    }
}
