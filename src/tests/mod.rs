//! Tests of the crate's internals that need more than one layer (robots in their table scene,
//! controllers and IK against an independent URDF forward kinematics, tasks with constructed
//! states): they use `pub(crate)` items, so they live inside the crate. Tests of the public
//! API and of the command line are in `tests/`.
mod clearance;
mod common;
mod drives;
mod fetch;
mod fetch_tasks;
mod foundation;
mod peg_insertion_side;
mod poke_cube;
mod push_t;
mod so100;
mod stack;
mod widowxai;
mod xarm6;
