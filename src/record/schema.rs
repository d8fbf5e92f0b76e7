//! JSON Schemas of the recording's channels and the Foxglove message builders.
//!
//! The Foxglove schemas follow the published `foxglove.FrameTransforms` and
//! `foxglove.SceneUpdate` JSON schemas (field names and nesting), trimmed to the fields the
//! recorder writes.

use serde_json::{json, Value};

use crate::mujoco::{Data, Model, ObjType};

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

fn env_state() -> Value {
    json!({
        "type": "object",
        "description": "mjskill EnvState (Env::get_state / Env::set_state)",
        "properties": {
            "env_id": { "type": "string" },
            "robot": { "type": "string" },
            "control_mode": { "type": "string" },
            "physics": { "type": "array", "items": { "type": "number" } },
            "controller": { "type": "array", "items": { "type": "number" } },
            "elapsed_steps": { "type": "integer" }
        },
        "required": ["env_id", "robot", "control_mode", "physics", "controller", "elapsed_steps"]
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
        "required": ["episode", "seed", "state", "obs", "info"]
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
            "obs": num_array(),
            "reward": num_or_null(),
            "terminated": { "type": "boolean" },
            "truncated": { "type": "boolean" },
            "info": info_object(),
            "state_before": env_state()
        },
        "required": ["episode", "step", "action", "obs", "reward", "terminated", "truncated",
                     "info", "state_before"]
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
        "required": ["episode", "steps", "return", "success"]
    })
}

fn time_schema() -> Value {
    json!({
        "type": "object",
        "properties": {
            "sec": { "type": "integer", "minimum": 0 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999999999 }
        }
    })
}

fn vector3_schema() -> Value {
    json!({
        "type": "object",
        "properties": {
            "x": { "type": "number" }, "y": { "type": "number" }, "z": { "type": "number" }
        }
    })
}

fn quaternion_schema() -> Value {
    json!({
        "type": "object",
        "properties": {
            "x": { "type": "number" }, "y": { "type": "number" },
            "z": { "type": "number" }, "w": { "type": "number" }
        }
    })
}

fn pose_schema() -> Value {
    json!({
        "type": "object",
        "properties": { "position": vector3_schema(), "orientation": quaternion_schema() }
    })
}

fn color_schema() -> Value {
    json!({
        "type": "object",
        "properties": {
            "r": { "type": "number" }, "g": { "type": "number" },
            "b": { "type": "number" }, "a": { "type": "number" }
        }
    })
}

/// Schema `foxglove.FrameTransforms`.
pub(crate) fn frame_transforms() -> Value {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "foxglove.FrameTransforms",
        "description": "An array of FrameTransform messages",
        "type": "object",
        "properties": {
            "transforms": {
                "type": "array",
                "items": {
                    "title": "foxglove.FrameTransform",
                    "type": "object",
                    "properties": {
                        "timestamp": time_schema(),
                        "parent_frame_id": { "type": "string" },
                        "child_frame_id": { "type": "string" },
                        "translation": vector3_schema(),
                        "rotation": quaternion_schema()
                    }
                }
            }
        }
    })
}

/// Schema `foxglove.SceneUpdate`.
pub(crate) fn scene_update() -> Value {
    let prim = |title: &str, extra: Value| {
        let mut p = json!({
            "pose": pose_schema(),
            "size": vector3_schema(),
            "color": color_schema()
        });
        if let (Some(p), Value::Object(e)) = (p.as_object_mut(), extra) {
            p.extend(e);
        }
        json!({ "title": title, "type": "object", "properties": p })
    };
    let any_array = json!({ "type": "array" });
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "foxglove.SceneUpdate",
        "description": "An update to the entities displayed in a 3D scene",
        "type": "object",
        "properties": {
            "deletions": {
                "type": "array",
                "items": {
                    "title": "foxglove.SceneEntityDeletion",
                    "type": "object",
                    "properties": {
                        "timestamp": time_schema(),
                        "type": { "type": "integer", "enum": [0, 1] },
                        "id": { "type": "string" }
                    }
                }
            },
            "entities": {
                "type": "array",
                "items": {
                    "title": "foxglove.SceneEntity",
                    "type": "object",
                    "properties": {
                        "timestamp": time_schema(),
                        "frame_id": { "type": "string" },
                        "id": { "type": "string" },
                        "lifetime": time_schema(),
                        "frame_locked": { "type": "boolean" },
                        "metadata": {
                            "type": "array",
                            "items": {
                                "type": "object",
                                "properties": {
                                    "key": { "type": "string" }, "value": { "type": "string" }
                                }
                            }
                        },
                        "arrows": any_array,
                        "cubes": { "type": "array",
                                   "items": prim("foxglove.CubePrimitive", json!({})) },
                        "spheres": { "type": "array",
                                     "items": prim("foxglove.SpherePrimitive", json!({})) },
                        "cylinders": { "type": "array",
                                       "items": prim("foxglove.CylinderPrimitive", json!({
                                           "bottom_scale": { "type": "number" },
                                           "top_scale": { "type": "number" }
                                       })) },
                        "lines": any_array,
                        "triangles": any_array,
                        "texts": any_array,
                        "models": any_array
                    }
                }
            }
        }
    })
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
    let (xpos, xquat) = (data.xpos(), data.xquat());
    let t = time(ns);
    let transforms: Vec<Value> = (1..frames.len())
        .map(|b| {
            let p = &xpos[3 * b..3 * b + 3];
            let q = &xquat[4 * b..4 * b + 4];
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
    let (ty, size, rgba) = (model.geom_type(), model.geom_size(), model.geom_rgba());
    let (pos, quat) = (model.geom_pos(), model.geom_quat());
    let (body, group) = (model.geom_bodyid(), model.geom_group());
    let mut per_body: Vec<[Vec<Value>; 3]> = vec![Default::default(); frames.len()];
    for g in 0..model.ngeom() {
        let c = &rgba[4 * g..4 * g + 4];
        if c[3] <= 0.0 || group[g] == crate::mjcf::GROUP_COLLISION {
            continue;
        }
        let s = &size[3 * g..3 * g + 3];
        let p = &pos[3 * g..3 * g + 3];
        let q = &quat[4 * g..4 * g + 4];
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

/// Schema `foxglove.CompressedImage` (JSON encoding: `data` is base64).
pub(crate) fn compressed_image() -> Value {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "foxglove.CompressedImage",
        "description": "A compressed image",
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "frame_id": {
                "type": "string",
                "description": "Frame of reference for the image (the camera's name)"
            },
            "data": {
                "type": "string",
                "contentEncoding": "base64",
                "description": "Compressed image data"
            },
            "format": { "type": "string", "description": "Image format: png" }
        }
    })
}

/// A `foxglove.CompressedImage` message with base64 `data`.
#[derive(serde::Serialize, serde::Deserialize)]
pub(crate) struct CompressedImageMsg<'a> {
    pub(crate) timestamp: Value,
    pub(crate) frame_id: &'a str,
    pub(crate) data: &'a str,
    pub(crate) format: &'a str,
}
