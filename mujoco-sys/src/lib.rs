//! Raw, generated FFI bindings to MuJoCo 2.2 (`libmujoco-dev` 2.2.2 on Debian 12).
//!
//! Everything here is `unsafe` and mirrors `mujoco.h` one to one. Use the safe layer in the
//! `mjskill` crate (`mjskill::mujoco`) instead of calling these directly.
#![allow(
    non_upper_case_globals,
    non_camel_case_types,
    non_snake_case,
    missing_docs
)]
#![allow(clippy::all)]

include!(concat!(env!("OUT_DIR"), "/bindings.rs"));

/// The MuJoCo version these bindings were generated for (`mjVERSION_HEADER`, 222 for 2.2.2).
pub const HEADER_VERSION: i32 = mjVERSION_HEADER as i32;
