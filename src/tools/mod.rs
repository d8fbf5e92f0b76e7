//! Authoring tools that are not part of the runtime data path: primitive fitting for the
//! robots' collision shapes (`mjskill fit-primitives`, [`mesh_fit`]).
pub mod mesh_fit;
